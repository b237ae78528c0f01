"""Compile plenocli's numba kernels into numba's on-disk cache (``cache=True``).

A kernel is compiled the first time it is called with a new type signature; with
``cache=True`` the machine code is kept beside the module (``__pycache__/*.nbi, *.nbc``) and
later processes load it instead of compiling. Without a warm cache the first ``plenocli
refocus`` on a fresh install spends about 10 s compiling. ``make`` runs this module right after
installing; after a manual ``pip install`` run ``python -m plenocli.warmup`` once. The kernels
are called on tiny inputs with exactly the argument types the stages use, so every signature a
stage needs is cached. See docs/startup.md.
"""

from __future__ import annotations

import time

import numpy as np


def warm_refocus() -> None:
    """Every refocus kernel signature: mono and Bayer frames (float32 after conversion)."""
    from plenocli.model.lensgrid import LensGrid
    from plenocli.refocus import refocus

    grid = LensGrid(pitch_px=8.0, angle_rad=0.1, offset_xy=(20.0, 20.0), image_shape=(48, 48))
    frame = np.ones((48, 48), np.uint16)
    refocus(frame, grid, s=0.5, g=2.0)
    refocus(frame, grid, s=0.5, g=2.0, view="left", cfa="RGGB")


def warm_calibrate() -> None:
    """The calibration kernels (border contrast, micro-image symmetry centres)."""
    from plenocli.calibration import calibrate
    from plenocli.synth.whiteimage import white_image

    image, _ = white_image((256, 256), pitch_px=12.0, angle_rad=0.1, offset_xy=(128.0, 128.0))
    calibrate(image)


def warm_develop() -> None:
    """The RCD demosaic kernels (develop's and stitch's default) and the sRGB curve."""
    from plenocli.colour.demosaic import demosaic
    from plenocli.io.photo import encode

    demosaic(np.ones((64, 64), np.float32), "RGGB", gains=(2.0, 1.0, 1.5))
    encode(np.full((4, 4, 3), 0.5, np.float32), "srgb")


def warm_depth() -> None:
    """The depth kernels: a small simulated lenslet plane and a dual-pixel pair."""
    from plenocli.depth.lenslet import depth_map
    from plenocli.depth.views import disparity_x
    from plenocli.model.lensgrid import LensGrid
    from plenocli.refocus import output_shape
    from plenocli.synth.depthscene import disparity_views, lenslet_depth_frame, scene_planes

    shape = (120, 160)
    grid = LensGrid(20.2, 0.0, (5.3, 8.7), "hex", image_shape=shape)
    planes = scene_planes("plane", output_shape(shape, 0.2), g=4.0)
    depth_map(lenslet_depth_frame(grid, shape, planes, s=0.2, seed=1), grid, s=0.2)
    views = disparity_views((96, 96), [1.0], seed=1)[0]
    disparity_x(views[0], views[1])


def warm_stitch() -> None:
    """The photometric refinement's kernels: a small textured pair, with and without no-data
    pixels, and the rig maps' and blend's kernels."""
    from scipy import ndimage

    import plenocli.stitch.kernels  # noqa: F401
    from plenocli.stitch import refine_homography

    scene = ndimage.gaussian_filter(np.random.default_rng(0).random((64, 112)), 2.0) + 1.0
    a, b = scene[:, :64].astype(np.float32), scene[:, 48:].astype(np.float32)
    shift = np.array([[1.0, 0.0, 48.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    refine_homography(a, b, shift)
    b[30:34, 4:8] = np.nan
    refine_homography(a, b, shift)


WARMERS = {"refocus": warm_refocus, "calibrate": warm_calibrate, "develop": warm_develop,
           "depth": warm_depth, "stitch": warm_stitch}


def main() -> None:
    for name, warm in WARMERS.items():
        start = time.perf_counter()
        warm()
        print(f"plenocli warm-up: {name} kernels ready ({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
