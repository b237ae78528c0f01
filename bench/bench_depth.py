"""Benchmark: depth of an 8 Mpx lenslet frame against its refocus time, and dual-pixel
disparity of a 30 Mpx pair against a full-size cv2.remap of the same views.

Lenslet: a 3264 x 2448 frame of a textured plane at g = 4 (the simulator), hex pitch 20.2 px;
``plenocli.depth.lenslet.depth_map`` at s = 0.2 against ``refocus`` (Lanczos-3, g = 4, s = 0.2)
of the same frame, in the same run. Target: ratio <= 3.
Dual pixel: 6720 x 4480 views (a textured scene shifted by 1.3 px), ``disparity_x`` against
cv2.remap INTER_CUBIC of both views (the baseline: one full-size warp per view). Target:
<= 10 s on 2 cores. Numba compile time is excluded; each timing is the best of ``--repeat``.

    python bench/bench_depth.py [--repeat 3]
"""

from __future__ import annotations

import argparse

import cv2
import numba
import numpy as np

from bench.timing import best_time
from plenocli.depth.lenslet import depth_map
from plenocli.depth.views import disparity_x
from plenocli.model.lensgrid import LensGrid
from plenocli.refocus import refocus
from plenocli.synth.depthscene import lenslet_depth_frame


def lenslet(repeat: int) -> None:
    rows, cols = 2448, 3264
    grid = LensGrid(20.2, 0.0, (7.0, 5.0), "hex", image_shape=(rows, cols))
    planes = [{"a": 4.0, "bx": 0.0, "by": 0.0, "region": None}]
    frame = lenslet_depth_frame(grid, (rows, cols), planes, s=0.2, seed=1)
    depth_map(frame[:400, :400], grid, s=0.2)  # numba compile / cache
    refocus(frame[:400, :400], grid, s=0.2, g=4.0)
    t_depth = best_time(lambda: depth_map(frame, grid, s=0.2), repeat)[0]
    t_ref = best_time(lambda: refocus(frame, grid, s=0.2, g=4.0), repeat)[0]
    result = depth_map(frame, grid, s=0.2)
    known = np.isfinite(result.g)
    print(f"lenslet {cols} x {rows} ({rows * cols / 1e6:.1f} Mpx), pitch 20.2, plane g = 4")
    print(f"  depth   : {t_depth:.3f} s  (median g {np.median(result.g[known]):.3f}, "
          f"{100 * known.mean():.1f} % known)")
    print(f"  refocus : {t_ref:.3f} s")
    print(f"  ratio depth / refocus: {t_depth / t_ref:.2f}  (target <= 3)")


def dual_pixel(repeat: int) -> None:
    rows, cols = 4480, 6720
    rng = np.random.default_rng(0)
    scene = cv2.GaussianBlur(rng.random((rows, cols), dtype=np.float32), (0, 0), 1.5)
    # exact sub-pixel shifts (Fourier phase ramps), not an interpolator's approximation
    spectrum = np.fft.rfft(scene, axis=1)
    ramp = np.exp(2j * np.pi * np.fft.rfftfreq(cols) * 0.65)
    a = np.fft.irfft(spectrum * ramp, n=cols, axis=1).astype(np.float32)
    b = np.fft.irfft(spectrum / ramp, n=cols, axis=1).astype(np.float32)
    del spectrum
    xx = np.broadcast_to(np.arange(cols, dtype=np.float32), (rows, cols))
    yy = np.ascontiguousarray(np.broadcast_to(np.arange(rows, dtype=np.float32)[:, None],
                                              (rows, cols)))
    disparity_x(a[:256, :256], b[:256, :256])
    t_dp = best_time(lambda: disparity_x(a, b), repeat)[0]
    map_x = np.ascontiguousarray(xx + 0.3)
    t_remap = best_time(lambda: [cv2.remap(v, map_x, yy, cv2.INTER_CUBIC) for v in (a, b)],
                        repeat)[0]
    d = disparity_x(a, b).disparity
    print(f"dual pixel {cols} x {rows} ({rows * cols / 1e6:.1f} Mpx), true disparity 1.3 px")
    print(f"  disparity : {t_dp:.3f} s  (median {np.nanmedian(d):.3f} px)  (target <= 10 s)")
    print(f"  2 x cv2.remap cubic : {t_remap:.3f} s")
    print(f"  ratio disparity / remap: {t_dp / t_remap:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--only", choices=["lenslet", "dualpixel"], default=None)
    args = parser.parse_args()
    print(f"threads: numba {numba.get_num_threads()}, OpenCV {cv2.getNumThreads()}")
    if args.only != "dualpixel":
        lenslet(args.repeat)
    if args.only != "lenslet":
        dual_pixel(args.repeat)


if __name__ == "__main__":
    main()
