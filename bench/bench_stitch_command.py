"""Benchmark: the whole ``plenocli stitch`` command on a dual-pixel + prism capture with the rig,
against the floor of one Lanczos resampling per colour plane, measured in the same run.

A simulated capture (``simulate dualpixel-prism --pixels N``: views N x 2N/3, through decode,
bias and flat, Bayer views A and B in one TIFF) is stitched by the command of this checkout
(``plenocli stitch views.tif --views A,B --rig configs/rigs/dualpixel_prism.yaml``, a child
process: wall time and its own peak RSS from ``os.wait4``). Baselines, on the same views,
demosaiced once, in this process:

- six remaps: ``cv2.remap`` INTER_LANCZOS4 of each colour plane of both views at view size
  (the issue's floor);
- footprint floor: the same, each plane remapped into its view's footprint box on the panorama
  (the prism bends the views, so the footprints are larger than the views);
- demosaic: ``colour.demosaic`` of both views (the command must demosaic Bayer views; it is
  not the stitch's work and is printed apart).

With ``--batch N``, a transform saved by the first command is reapplied to N captures
(``--transform-in``): the time per capture against the footprint floor, as N separate commands
and as one ``plenocli batch`` over N copies of the capture (``--jobs 1`` and ``2``: the way a
shoot is processed, the start-up paid once per worker).

Memory: peak RSS of the command as a multiple of the bytes of the views (float32 RGB) plus the
panorama (float32 RGB). Run ``uptime`` first: the ratios are meaningful on a loaded machine,
the seconds are not.

With ``--baseline COMMIT`` the same command by that commit's code is timed after, in the same
run, and the largest difference of the shifts printed; the batch then runs both codes in turns.

    PYTHONPATH=. python bench/bench_stitch_command.py [--pixels 3072] [--batch 10] [--baseline C]
        [--views VIEWS.tif]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from bench.timing import ROOT, best_time, export_package

RIG = ROOT / "configs" / "rigs" / "dualpixel_prism.yaml"


def capture(folder: Path, pixels: int) -> Path:
    """views.tif (Bayer A, B, flat-fielded) of a simulated dual-pixel + prism capture."""
    from plenocli.pipeline.stages import bias, decode, flat, simulate

    for kind, name in (("dualpixel-prism", "capture"), ("dualpixel-white", "white")):
        simulate.simulate(kind, folder / name, pixels=pixels)
        decode.run(str(folder / name / "capture.dng"), str(folder / f"{name}_frames.tif"))
        bias.run(str(folder / f"{name}_frames.tif"), str(folder / f"{name}_biased.tif"))
    flat.run(str(folder / "capture_biased.tif"), str(folder / "views.tif"),
             white=str(folder / "white_biased.tif"))
    return folder / "views.tif"


def command(views: Path, out: Path, *extra: str,
            root: Path = ROOT) -> tuple[float, float, float]:
    """Wall seconds, peak RSS (bytes) and CPU seconds (user + system, every thread) of one
    ``plenocli stitch`` child process (the package under ``root``)."""
    argv = [sys.executable, "-m", "plenocli", "stitch", str(views), "--views", "A,B", "--rig",
            str(RIG), "-o", str(out), *extra]
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=root, env={**os.environ, "PYTHONPATH": str(root)},
                            stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    err = proc.stderr.read().decode()
    if status:
        raise RuntimeError(f"plenocli stitch failed:\n{err}")
    return seconds, usage.ru_maxrss * 1024.0, usage.ru_utime + usage.ru_stime


def floors(views: Path, report: dict, repeat: int) -> dict:
    """Seconds of the six view-size remaps, of the footprint remaps and of the demosaics."""
    from bench.bench_stitch_colour import mosaics
    from plenocli.colour.demosaic import demosaic
    from plenocli.stitch import PrismRig
    from plenocli.stitch.rig import _view_maps

    mosaic, cfa = mosaics(views)
    t_demosaic, rgb = best_time(lambda: [demosaic(v, cfa) for v in mosaic], repeat)
    planes = [np.ascontiguousarray(v[..., c]) for v in rgb for c in range(3)]
    rows, cols = planes[0].shape
    rig = PrismRig.from_dict(report["rig"])
    maps = []  # each view's rig map over its own size, and over its footprint's box
    footprint_px = 0.0
    for k in range(2):
        origin = np.array(report["canvas_origins_px"][k][::-1], float)
        for which, shape in enumerate(((rows, cols), tuple(report["canvas_shape"]))):
            parts = list(_view_maps(rig, k, origin, shape, (rows, cols)))
            mx, my = (np.concatenate([p[i] for p in parts]) for i in (1, 2))
            if which:  # the box of the canvas pixels the view covers, off-view pixels pointed
                # inside (as the stitch does: OpenCV's border path is slow)
                on = (mx >= 0) & (mx <= cols - 1) & (my >= 0) & (my <= rows - 1)
                r, c = np.flatnonzero(on.any(axis=1)), np.flatnonzero(on.any(axis=0))
                box = (slice(r[0], r[-1] + 1), slice(c[0], c[-1] + 1))
                mx, my, on = mx[box], my[box], on[box]
                mx, my = np.where(on, mx, np.float32(4)), np.where(on, my, np.float32(4))
                footprint_px += mx.size / 2
            maps.append((np.ascontiguousarray(mx), np.ascontiguousarray(my)))

    def remap(which: int):
        for k in range(2):
            mx, my = maps[2 * k + which]
            for plane in planes[3 * k:3 * k + 3]:
                cv2.remap(plane, mx, my, cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REPLICATE)

    t_six, _ = best_time(lambda: remap(0), repeat)
    cpu = time.process_time()
    t_foot, _ = best_time(lambda: remap(1), repeat)
    cpu_foot = (time.process_time() - cpu) / repeat
    return {"six": t_six, "footprint": t_foot, "footprint_cpu": cpu_foot, "demosaic": t_demosaic,
            "views_bytes": 4.0 * 6 * rows * cols, "footprint_px": footprint_px,
            "view_px": float(rows * cols)}


def batch(views: Path, folder: Path, runs: list[tuple[Path, Path]],
          n: int) -> list[tuple[float, float]]:
    """Wall and CPU seconds per capture of ``n`` commands reapplying a saved transform, for
    each (package root, transform) of ``runs``; the roots take turns, so they share the load."""
    times = [[] for _ in runs]
    for k in range(n):
        for j, (root, transform) in enumerate(runs):
            times[j].append(command(views, folder / f"batch{j}_{k}.tif", "--transform-in",
                                    str(transform), root=root))
    return [(sum(t[0] for t in ts) / n, sum(t[2] for t in ts) / n) for ts in times]


BATCH_CONFIG = """steps:
  stitch:
    inputs: ["{{capture}}"]
    views: A,B
    rig: {rig}
    transform-in: {transform}
    output: "{{out}}/{{name}}/panorama.tif"
"""


def batch_command(views: Path, folder: Path, transform: Path, n: int, jobs: int) -> float:
    """Wall seconds per capture of one ``plenocli batch --jobs JOBS`` over ``n`` copies of the
    capture (copies: a capture is hashed for its record, as a new one would be). No CPU time:
    the workers are the fork server's children, not the command's."""
    captures = folder / "captures"
    captures.mkdir(exist_ok=True)
    for k in range(n):
        if not (captures / f"c{k:02d}.tif").exists():
            shutil.copyfile(views, captures / f"c{k:02d}.tif")
    config = folder / "batch_stitch.yaml"
    config.write_text(BATCH_CONFIG.format(rig=RIG, transform=transform))
    out = folder / f"batch_out_j{jobs}"
    argv = [sys.executable, "-m", "plenocli", "batch", str(config), "--inputs",
            str(captures / "*.tif"), "--out", str(out), "--jobs", str(jobs), "-q"]
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stderr=subprocess.PIPE)
    _, status, _ = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    if status:
        raise RuntimeError(f"plenocli batch failed:\n{proc.stderr.read().decode()}")
    shutil.rmtree(out)
    return seconds / n


def print_batch(label: str, n: int, per: tuple[float, float], base: dict) -> None:
    print(f"{label} batch of {n} with --transform-in: {per[0]:.2f} s per capture (CPU "
          f"{per[1]:.2f} s) = {per[0] / base['footprint']:.2f} x the footprint floor, "
          f"{(per[0] - base['demosaic']) / base['footprint']:.2f} x without the demosaic")


def print_command(label: str, t_cmd: float, rss: float, cpu: float, base: dict,
                  pano_bytes: float) -> None:
    print(f"{label} command {t_cmd:7.2f} s (CPU {cpu:6.2f} s)  peak RSS {rss / 2**20:6.0f} MiB = "
          f"{rss / (base['views_bytes'] + pano_bytes):.2f} x (views + panorama)")
    print(f"    / six remaps {t_cmd / base['six']:.2f} x; / footprint floor "
          f"{t_cmd / base['footprint']:.2f} x (CPU {cpu / base['footprint_cpu']:.2f} x); "
          f"(command - demosaic) / footprint floor "
          f"{(t_cmd - base['demosaic']) / base['footprint']:.2f} x")


def baseline(views: Path, folder: Path, commit: str, report: dict, base: dict,
             pano_bytes: float) -> tuple[Path, Path]:
    """The same command by the code of ``commit``, in the same run; returns that code's root
    and the transform it saved."""
    (folder / "baseline").mkdir()
    root = export_package(commit, folder / "baseline")
    # its numba kernels compiled into its own cache first, as `make` does after installing:
    # the time compared is the command's, not a first run's compilation
    subprocess.run([sys.executable, "-m", "plenocli.warmup"], cwd=root, check=True,
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(root)})
    rep_file, transform = folder / "report_baseline.json", folder / "transform_baseline.json"
    t_cmd, rss, cpu = command(views, folder / "pano_baseline.tif", "--report", str(rep_file),
                              "--transform-out", str(transform), root=root)
    shifts = np.array(json.loads(rep_file.read_text())["shifts_px"])
    moved = float(np.abs(shifts - np.array(report["shifts_px"])).max())
    print_command(f"baseline {commit}", t_cmd, rss, cpu, base, pano_bytes)
    print(f"    shifts differ from this checkout's by {moved:.4f} px at most")
    return root, transform


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pixels", type=int, default=3072)
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--batch", type=int, default=0)
    parser.add_argument("--baseline", default=None, help="a commit whose command is timed too")
    parser.add_argument("--views", default=None, help="a views.tif made by capture() before "
                        "(skips simulating one)")
    args = parser.parse_args()
    print("load:", os.getloadavg(), f"OpenCV threads {cv2.getNumThreads()}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        views = Path(args.views) if args.views else capture(folder, args.pixels)
        rep_file, transform = folder / "report.json", folder / "transform.json"
        t_cmd, rss, cpu = min(command(views, folder / "pano.tif", "--report", str(rep_file),
                                      "--transform-out", str(transform))
                              for _ in range(args.repeat))
        report = json.loads(rep_file.read_text())
        base = floors(views, report, args.repeat)
        pano_bytes = 4.0 * 3 * np.prod(report["panorama_shape"])
        print(f"views {report['view_shape'][1]} x {report['view_shape'][0]}, panorama "
              f"{report['panorama_shape'][1]} x {report['panorama_shape'][0]}, footprint boxes "
              f"{base['footprint_px'] / base['view_px']:.2f} x the view (mean of A, B)")
        print(f"six remaps (view size)    {base['six']:7.2f} s")
        print(f"footprint remaps          {base['footprint']:7.2f} s (CPU "
              f"{base['footprint_cpu']:.2f} s): the floor")
        print(f"demosaic of A and B       {base['demosaic']:7.2f} s (inside the command)")
        print_command("this checkout", t_cmd, rss, cpu, base, pano_bytes)
        runs = [("this checkout", (ROOT, transform))]
        if args.baseline:
            runs.append((f"baseline {args.baseline}",
                         baseline(views, folder, args.baseline, report, base, pano_bytes)))
        if args.batch:  # the checkout and the baseline in turns
            for (label, _), per in zip(runs, batch(views, folder, [r for _, r in runs],
                                                   args.batch), strict=True):
                print_batch(label, args.batch, per, base)
            for jobs in (1, 2):
                per = batch_command(views, folder, transform, args.batch, jobs)
                print(f"this checkout, plenocli batch --jobs {jobs} of {args.batch} with "
                      f"--transform-in: {per:.2f} s per capture = "
                      f"{per / base['footprint']:.2f} x the footprint floor")
        print("load:", os.getloadavg())


if __name__ == "__main__":
    main()
