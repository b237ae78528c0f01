"""Stitching Bayer views: full-resolution demosaiced RGB (now) vs half-size RGB (before).

The demo's dual-pixel capture (``out/demo/dualpixel_stitch/clean.tif``, the unmixed A and B
views of ``make demo``; when it is missing, a ``simulate dualpixel-prism --pixels 768`` capture
through decode, bias and flat, the same size), stitched with the demo's rig both ways in the same
run: the views made RGB (``colour.demosaic``, the default method, at full resolution; or
``model.cfa.half_size_rgb``, one RGB pixel per 2 x 2 cell), then ``stitch.stitch``. Times are
the best of ``--repeat`` runs; file I/O is left out. Memory: the tracemalloc peak of numpy
allocations during one more run of each.

    PYTHONPATH=. python bench/bench_stitch_colour.py [--views FILE.tif] [--repeat 3]
"""

from __future__ import annotations

import argparse
import tempfile
import tracemalloc
from pathlib import Path

import numpy as np

from bench.timing import best_time
from plenocli.colour.demosaic import demosaic
from plenocli.io import tiffio
from plenocli.io.rigfile import read_rig as load_rig
from plenocli.model.cfa import half_size_rgb, shift_pattern
from plenocli.stitch import stitch

ROOT = Path(__file__).resolve().parents[1]
DEMO_VIEWS = ROOT / "out" / "demo" / "dualpixel_stitch" / "clean.tif"
RIG = ROOT / "configs" / "rigs" / "dualpixel_prism.yaml"


def simulated_views(folder: Path) -> Path:
    """Flat-fielded A, B (and S) views of a simulated dual-pixel + prism capture."""
    from plenocli.pipeline.stages import bias, decode, flat, simulate

    for kind, name in (("dualpixel-prism", "capture"), ("dualpixel-white", "white")):
        simulate.simulate(kind, folder / name, pixels=768)
        decode.run(str(folder / name / "capture.dng"), str(folder / f"{name}_frames.tif"))
        bias.run(str(folder / f"{name}_frames.tif"), str(folder / f"{name}_biased.tif"))
    flat.run(str(folder / "capture_biased.tif"), str(folder / "views.tif"),
             white=str(folder / "white_biased.tif"))
    return folder / "views.tif"


def mosaics(path: Path) -> tuple[np.ndarray, str]:
    """Views A and B (2, rows, cols) of the active area, and their CFA pattern."""
    data, meta = tiffio.read_image(path)
    top, left, bottom, right = meta["active_area"]
    names = list(meta["views"])
    views = np.stack([data[names.index(v), top:bottom, left:right] for v in "AB"])
    return views.astype(np.float32), shift_pattern(meta["cfa"], top, left)


def run_case(views: np.ndarray, cfa: str, rgb_of, rig, repeat: int):
    """Best time, the last result and the numpy peak (bytes) of one run."""
    def once():
        stack = np.stack([np.moveaxis(rgb_of(v, cfa), -1, 0) for v in views])
        return stitch(stack, layout="1x2", rig=rig)

    seconds, result = best_time(once, repeat)
    tracemalloc.start()
    once()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return seconds, result, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=Path, default=DEMO_VIEWS)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rig = load_rig(str(RIG))
    with tempfile.TemporaryDirectory() as tmp:
        source = args.views if args.views.is_file() else simulated_views(Path(tmp))
        views, cfa = mosaics(source)
    what = source if source == args.views else "a simulated dualpixel-prism capture"
    print(f"views A, B of {what}: {views.shape[2]} x {views.shape[1]} {cfa}")
    results = {}
    for name, rgb_of in (("half-size RGB (before)", half_size_rgb),
                         ("full-resolution demosaic", demosaic)):
        seconds, (pano, report), peak = run_case(views, cfa, rgb_of, rig, args.repeat)
        results[name] = seconds, peak
        print(f"{name:26s} {seconds:6.2f} s   panorama {pano.shape[2]} x {pano.shape[1]}, "
              f"residual {report.residual_px:.3f} px (in its own pixels), numpy peak "
              f"{peak / 2**20:.0f} MiB = {peak / pano.nbytes:.1f} x the panorama")
    (half, half_peak), (full, full_peak) = results.values()
    print(f"ratio full / half-size = {full / half:.2f} x the time, {full_peak / half_peak:.2f} x "
          "the memory, for 4 x the pixels")


if __name__ == "__main__":
    main()
