"""Benchmark `plenocli calibrate`: a 2048 x 2048 synthetic white image in memory, real scene
frames through the whole command (process start, imports, file reading, YAML writing), and a
31 Mpx frame (a real frame upsampled). The machine-speed baseline, measured in the same run, is
one numpy rfft2 of the same image; times are printed in seconds and as ratios to it. The whole
command is also timed in CPU seconds (user + system of the child process): on a shared machine
the wall time grows with the load, the CPU time much less. Peak memory (tracemalloc, in memory)
is printed as a multiple of the float32 image. With ``--baseline COMMIT`` the white image is
also calibrated by that commit's code and by this checkout's, each in a fresh process one
after the other, and the ratio of their times printed (each side draws the white image with
its own generator: compare commits whose ``plenocli.synth`` draws it alike).

    PYTHONPATH=. .venv/bin/python bench/bench_calibrate.py [REALDATA_DIR] [--baseline COMMIT]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import cv2
import numpy as np

from bench.timing import ROOT, best_time, export_package, run_python
from plenocli import calibration
from plenocli.synth.whiteimage import white_image


def _baseline(image: np.ndarray) -> float:
    data = image.astype(np.float32)
    return best_time(lambda: np.fft.rfft2(data), 3)[0]


def _in_memory(name: str, image: np.ndarray, target_s: float, repeat: int = 3) -> None:
    """Best wall and CPU time (every thread: FFT workers, numba) of ``repeat`` calls."""
    base = _baseline(image)
    took, cpu = np.inf, np.inf
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        calibration.calibrate(image)
        took = min(took, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    tracemalloc.start()
    calibration.calibrate(image)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    ratio_mem = peak / (image.size * 4)
    print(f"{name}: {took:.2f} s (target {target_s} s), {took / base:.0f} x rfft2 "
          f"({base * 1e3:.0f} ms), CPU {cpu:.2f} s; peak memory {ratio_mem:.1f} x the float32 "
          "image (target 5)")


def _command(name: str, path: Path, target_s: float, shape: tuple[int, int],
             repeat: int = 2) -> None:
    """Best wall and CPU time of ``repeat`` runs of the command in a fresh process."""
    frame = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float32)
    base = _baseline(frame.sum(-1) if frame.ndim == 3 else frame)
    plenocli = Path(sys.executable).with_name("plenocli")
    wall, cpu = np.inf, np.inf
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "grid.yaml"
        for _ in range(repeat):
            before, t = os.times(), time.perf_counter()
            res = subprocess.run([str(plenocli), "calibrate", str(path), "-o", str(out)],
                                 capture_output=True, text=True)
            after = os.times()
            wall = min(wall, time.perf_counter() - t)
            cpu = min(cpu, after.children_user - before.children_user
                      + after.children_system - before.children_system)
    status = "ok" if res.returncode == 0 else f"exit {res.returncode}: {res.stderr.strip()}"
    print(f"{name} ({shape[1]} x {shape[0]}), whole command: {wall:.2f} s (target {target_s} s), "
          f"{wall / base:.0f} x rfft2 ({base * 1e3:.0f} ms), CPU {cpu:.2f} s; {status}")


WHITE_RUNNER = """
import sys, time
import numpy as np
from plenocli import calibration
from plenocli.synth.whiteimage import white_image
warm, _ = white_image((256, 256), pitch_px=12.0, angle_rad=0.1, offset_xy=(128, 128))
calibration.calibrate(warm)
white, _ = white_image((2048, 2048), pitch_px=20.2, angle_rad=0.05, offset_xy=(1024.3, 1024.6),
                       seed=1)
image, best = white.astype(np.float32) - 64, float("inf")
for _ in range(5):
    start = time.perf_counter()
    calibration.calibrate(image)
    best = min(best, time.perf_counter() - start)
print(best)
"""


def _against(commit: str) -> None:
    """The white image by ``commit``'s code and by this checkout's, in fresh processes."""
    with tempfile.TemporaryDirectory() as tmp:
        seconds = {}
        for name, root in ((f"baseline {commit}", export_package(commit, Path(tmp))),
                           ("this checkout", ROOT)):
            seconds[name] = float(run_python(WHITE_RUNNER, root=root).split()[-1])
            print(f"white 2048 x 2048 in memory, {name}: {seconds[name]:.3f} s", flush=True)
        before, after = seconds.values()
        print(f"ratio this / baseline: {after / before:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("realdata", nargs="?", default="../shared/realdata")
    parser.add_argument("--baseline", help="a git commit to compare the white image with")
    args = parser.parse_args()
    realdata = Path(args.realdata) / "raytrix"
    warm, _ = white_image((256, 256), pitch_px=12.0, angle_rad=0.1, offset_xy=(128, 128))
    calibration.calibrate(warm)   # compile (or load) the numba kernels
    white, _ = white_image((2048, 2048), pitch_px=20.2, angle_rad=0.05,
                           offset_xy=(1024.3, 1024.6), seed=1)
    _in_memory("white 2048 x 2048 in memory", white.astype(np.float32) - 64, 0.3, repeat=5)
    if args.baseline:
        _against(args.baseline)
    frames = {"origami 4 Mpx": realdata / "origami" / "frame0.png",
              "boys2 12 Mpx": realdata / "boys2_galilean" / "frame0.png",
              # borders smeared: the fold judge decides, the regions pin the pitch
              "fujita2 QP 48 4 Mpx": realdata / "compressed" / "fujita2_qp48.png"}
    for name, path in frames.items():
        if path.exists():
            shape = cv2.imread(str(path)).shape[:2]
            _command(name, path, 3.0, shape)
    origami = realdata / "origami" / "frame0.png"
    if origami.exists():   # 31 Mpx: the real frame upsampled 2.75 x (pitch 63.8 px)
        frame = cv2.imread(str(origami)).astype(np.float32).sum(-1)
        big = cv2.resize(frame, None, fx=2.75, fy=2.75, interpolation=cv2.INTER_CUBIC)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "big.png"
            cv2.imwrite(str(path), np.clip(big / 3, 0, 255).astype(np.uint8))
            _command("origami x 2.75 (31 Mpx)", path, 8.0, big.shape)
        _in_memory("origami x 2.75 (31 Mpx) in memory", big, 8.0, repeat=1)


if __name__ == "__main__":
    main()
