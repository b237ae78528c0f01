"""Benchmark: Lanczos-3 splatting refocus (paper Eq. 3) vs OpenCV cv2.remap INTER_LANCZOS4.

A 6720 x 4480 float32 frame (a full Raytrix-R5-class sensor) with a hex grid of pitch 20.2 px
is refocused at s = 0.2, g = 4 (paper values). The baseline, in the same run, is cv2.remap with
INTER_LANCZOS4 on the same frame: a full-size sub-pixel warp (maps x + 0.37, y + 0.21), i.e. one
8 x 8-tap Lanczos interpolation per sensor pixel, as many pixels as the splatting touches.
Numba compile time is excluded (warm-up on a small crop first); each timing is the best of
``--repeat`` runs. Memory: tracemalloc peak of the numpy allocations made by refocus (the input
frame excluded), and the process peak RSS (ru_maxrss) measured after refocus and before the
remap maps exist.

    python bench/bench_refocus.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import resource
import tracemalloc

import cv2
import numba
import numpy as np

from bench.timing import best_time
from plenocli.model.lensgrid import LensGrid
from plenocli.refocus import refocus

ROWS, COLS = 4480, 6720



def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    frame = rng.random((ROWS, COLS), dtype=np.float32)
    grid = LensGrid(pitch_px=20.2, angle_rad=np.pi / 2, offset_xy=(13.0, 9.0), lattice="hex",
                    image_shape=(ROWS, COLS))
    refocus(frame[:512, :512], grid, s=0.2, g=4.0, kernel="lanczos3")  # numba compile / cache

    def splat():
        return refocus(frame, grid, s=0.2, g=4.0, kernel="lanczos3")

    t_splat = best_time(splat, args.repeat)[0]
    tracemalloc.start()
    image, _ = splat()
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss_after_refocus = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

    yy, xx = np.mgrid[0:ROWS, 0:COLS].astype(np.float32)
    map_x, map_y = xx + np.float32(0.37), yy + np.float32(0.21)
    del xx, yy
    cv2.remap(frame[:256, :256], map_x[:256, :256], map_y[:256, :256], cv2.INTER_LANCZOS4)

    def remap():
        return cv2.remap(frame, map_x, map_y, cv2.INTER_LANCZOS4)

    t_remap = best_time(remap, args.repeat)[0]
    mpx = ROWS * COLS / 1e6
    print(f"frame {COLS} x {ROWS} float32 ({mpx:.1f} Mpx), hex pitch 20.2 px, s = 0.2, g = 4")
    print(f"threads: numba {numba.get_num_threads()}, OpenCV {cv2.getNumThreads()}")
    print(f"refocus lanczos3 splat : {t_splat:.3f} s  ({mpx / t_splat:.1f} Mpx/s), "
          f"output {image.shape[1]} x {image.shape[0]}")
    print(f"cv2.remap LANCZOS4     : {t_remap:.3f} s  ({mpx / t_remap:.1f} Mpx/s)")
    print(f"time ratio splat / remap: {t_splat / t_remap:.2f}  (target <= 2)")
    print(f"refocus numpy peak (tracemalloc, frame excluded): {traced_peak / 2**20:.0f} MiB")
    print(f"process peak RSS after refocus (frame included): {rss_after_refocus / 2**20:.0f} MiB"
          "  (target < 1024)")


if __name__ == "__main__":
    main()
