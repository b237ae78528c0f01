"""Full-resolution stitching of large colour views: this checkout against a baseline commit.

A simulated dual-pixel + prism capture (``simulate dualpixel-prism --pixels N``: views N x 2N/3,
through decode, bias and flat; or ``--views FILE.tif``), views A and B demosaiced once
(``colour.demosaic``), then ``stitch.stitch`` with the demo's rig by the code of this checkout
and by the code of ``--baseline`` (a git commit, exported with ``git archive``), each in its own
process, one after the other in the same run. Printed per variant: wall time (best of
``--repeat``, traced), the tracemalloc peak of the stitch (the views given to it excluded, they
are the caller's) as MiB and as a multiple of the float32 RGB panorama; then the ratios and
how far the panoramas and shifts differ.

    PYTHONPATH=. python bench/bench_stitch_memory.py [--pixels 1536] [--baseline 11b8dca]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.timing import ROOT, export_package, run_python

RUNNER = """
import json, sys, time, tracemalloc
import numpy as np
try:
    from plenocli.io.rigfile import read_rig as load_rig
except ImportError:  # a baseline commit from before the rig file moved to io/
    from plenocli.pipeline.stages.stitch import load_rig
from plenocli.stitch import stitch
stack = np.load(sys.argv[1])
rig = load_rig(sys.argv[2])
times, peak, pano = [], 0, None
tracemalloc.start()
for _ in range(int(sys.argv[4])):
    del pano
    tracemalloc.reset_peak()
    start = time.perf_counter()
    pano, report = stitch(stack, layout="1x2", rig=rig)
    times.append(time.perf_counter() - start)
    peak = max(peak, tracemalloc.get_traced_memory()[1])
tracemalloc.stop()
np.save(sys.argv[3], pano)
print(json.dumps({"seconds": min(times), "peak": peak, "pano_bytes": pano.nbytes,
                  "shape": list(pano.shape), "shifts": report.shifts_px,
                  "residual": report.residual_px}))
"""


def _views(args, folder: Path) -> np.ndarray:
    """Views A and B demosaiced, (2, 3, rows, cols) float32."""
    sys.path.insert(0, str(ROOT))
    from bench.bench_stitch_colour import mosaics
    from plenocli.colour.demosaic import demosaic
    from plenocli.pipeline.stages import bias, decode, flat, simulate

    source = args.views
    if source is None:
        for kind, name in (("dualpixel-prism", "capture"), ("dualpixel-white", "white")):
            simulate.simulate(kind, folder / name, pixels=args.pixels)
            decode.run(str(folder / name / "capture.dng"), str(folder / f"{name}_frames.tif"))
            bias.run(str(folder / f"{name}_frames.tif"), str(folder / f"{name}_biased.tif"))
        flat.run(str(folder / "capture_biased.tif"), str(folder / "views.tif"),
                 white=str(folder / "white_biased.tif"))
        source = folder / "views.tif"
    mosaic, cfa = mosaics(source)
    return np.stack([np.moveaxis(demosaic(v, cfa), -1, 0) for v in mosaic])


def _run(code_root: Path, stack_file: Path, out: Path, repeat: int) -> dict:
    printed = run_python(RUNNER, str(stack_file),
                         str(ROOT / "configs" / "rigs" / "dualpixel_prism.yaml"), str(out),
                         str(repeat), root=code_root)
    return json.loads(printed.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=1536)
    parser.add_argument("--views", type=Path, default=None)
    parser.add_argument("--baseline", default="11b8dca")
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        stack = _views(args, folder)
        np.save(folder / "stack.npy", stack)
        print(f"views A, B: {stack.shape[3]} x {stack.shape[2]} RGB float32, "
              f"{stack.nbytes / 2**20:.0f} MiB")
        del stack
        base = folder / "baseline"
        base.mkdir()
        export_package(args.baseline, base)
        results = {}
        for name, root in ((f"baseline {args.baseline}", base), ("this checkout", ROOT)):
            res = _run(root, folder / "stack.npy", folder / f"{len(results)}.npy", args.repeat)
            results[name] = res
            print(f"{name:20s} {res['seconds']:7.2f} s   panorama {res['shape'][2]} x "
                  f"{res['shape'][1]}, stitch peak {res['peak'] / 2**20:6.0f} MiB = "
                  f"{res['peak'] / res['pano_bytes']:.1f} x the panorama, residual "
                  f"{res['residual']:.4f} px", flush=True)
        before, after = results.values()
        pano_a, pano_b = np.load(folder / "0.npy"), np.load(folder / "1.npy")
        same_nan = np.array_equal(np.isnan(pano_a), np.isnan(pano_b))
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = float(np.nanmax(np.abs(pano_a - pano_b) / np.abs(pano_a)))
        shift = float(np.abs(np.array(before["shifts"]) - np.array(after["shifts"])).max())
        print(f"ratio this / baseline: {after['seconds'] / before['seconds']:.2f} x the time, "
              f"{after['peak'] / before['peak']:.2f} x the memory; panoramas: same NaN pixels "
              f"{same_nan}, largest relative difference {rel:.1e}; shifts differ by "
              f"{shift:.1e} px")


if __name__ == "__main__":
    main()
