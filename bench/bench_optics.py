"""Benchmark: ray-tracing throughput through the paper's Table 2 lens, and the time to simulate
a full-size 3000 x 3000 quad-pixel capture.

    python bench/bench_optics.py [--rays 2000000] [--pixels 3000]

Prints rays per second (with a baseline: the same rays through one flat surface, the cost floor
of the vectorised tracer), the simulation time, and peak memory (RSS).
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from plenocli.io.lensfile import read_lens  # noqa: E402
from plenocli.optics.fasttrace import trace_fast  # noqa: E402
from plenocli.optics.lens import Lens, Surface, trace  # noqa: E402
from plenocli.pipeline.stages.simulate import simulate  # noqa: E402
from plenocli.synth.prismcam import render_quadpixel  # noqa: E402


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def rays_for(count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    r = 1.5 * np.sqrt(rng.random(count))
    phi = 2 * np.pi * rng.random(count)
    pos = np.stack([r * np.cos(phi), r * np.sin(phi), np.full(count, -1.0)], 1)
    d = np.column_stack([rng.normal(0, 0.15, (count, 2)), np.ones(count)])
    return pos, d


def timed(fn, repeat=3):
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=2_000_000)
    parser.add_argument("--pixels", type=int, default=3000)
    args = parser.parse_args()
    t0 = time.perf_counter()
    sensor, truth = render_quadpixel(pixels=args.pixels, rays=1, seed=0)
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    render_quadpixel(pixels=args.pixels // 10 // 2 * 2, rays=1, seed=0)
    t_small = time.perf_counter() - t0
    print(f"simulate quad-pixel pyramid {args.pixels} x {args.pixels} (1 ray/pixel, chart "
          f"{truth['chart']['px']} px): {t_sim:.2f} s "
          f"({args.pixels ** 2 / t_sim / 1e6:.1f} M pixels/s); "
          f"1/10 size: {t_small:.3f} s (ratio {t_sim / t_small:.0f} for 100x the pixels)")
    print(f"peak RSS after simulating: {peak_rss_mb():.0f} MB (sensor image float32 RGB: "
          f"{sensor.nbytes / 2 ** 20:.0f} MB)")
    del sensor
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        simulate("quadpixel-pyramid", tmp, pixels=args.pixels, seed=0)
        t_write = time.perf_counter() - t0
    print(f"plenocli simulate quadpixel-pyramid --pixels {args.pixels} (render + 16-bit TIFF + "
          f"truth.json): {t_write:.2f} s")
    rng = np.random.default_rng(0)
    lens = read_lens(ROOT / "configs" / "lenses" / "paper_table2.yaml")
    flat = Lens((Surface(),), image_distance_mm=1.0)
    pos, d = rays_for(args.rays, rng)
    t_lens = timed(lambda: trace(lens, pos, d))
    t_flat = timed(lambda: trace(flat, pos, d))
    n_surf = len(lens.surfaces)
    print(f"tracer: {args.rays:,} rays through {lens.name} ({n_surf} surfaces): "
          f"{t_lens:.3f} s = {args.rays / t_lens / 1e6:.2f} M rays/s "
          f"({args.rays * n_surf / t_lens / 1e6:.1f} M ray-surfaces/s)")
    print(f"baseline: one flat surface: {t_flat:.3f} s = {args.rays / t_flat / 1e6:.2f} M rays/s;"
          f" per-surface cost ratio {t_lens / n_surf / t_flat:.2f}")
    trace_fast(lens, pos[:10], d[:10])  # compile once (cached on disk afterwards)
    t_fast = timed(lambda: trace_fast(lens, pos, d))
    t_fast1 = timed(lambda: trace_fast(lens, pos, d, parallel=False))
    print(f"compiled (numba) tracer: {t_fast:.3f} s = {args.rays / t_fast / 1e6:.2f} M rays/s "
          f"on all cores, {args.rays / t_fast1 / 1e6:.2f} M rays/s on one; "
          f"{t_lens / t_fast:.1f} x the numpy tracer")
    print(f"peak RSS after tracing: {peak_rss_mb():.0f} MB")


if __name__ == "__main__":
    main()
