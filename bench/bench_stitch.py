"""Benchmark: plenocli stitch (translation, homography) vs OpenCV baselines in the same run.

Cases: two 3000 x 3000 views side by side (30 % overlap) and a 2 x 2 of 1500 x 1500 views
(30 % overlap), rendered from one analytic band-limited scene (``plenocli.synth.rig.random_scene``,
a sum of 64 cosines evaluated at each view's warped pixel coordinates: no resampler shared with
the estimator) with a known sub-pixel translation or homography (corners moved by up to 4 px),
10 % vignetting, different gains and noise 0.003.

Baselines, measured on the same views:
- translation: ``cv2.phaseCorrelate`` (Hanning window) on the full pair, registration only,
  i.e. the textbook sub-pixel shift estimate (no panorama);
- homography: ``cv2.Stitcher`` in SCANS mode (affine model, OpenCV's own feature matching,
  bundle adjustment, exposure compensation and multi-band blending) producing a panorama;
  skipped with a note when OpenCV cannot stitch the views.
Times are the best of ``--repeat`` runs (end to end: registration + gains + blending for
plenocli). Memory: tracemalloc peak of numpy allocations during one plenocli run and the
process peak RSS (ru_maxrss) after it. Errors are against the known geometry: shift error (px)
and the far-corner error of the homography (px).

    PYTHONPATH=. python bench/bench_stitch.py [--repeat 1] [--skip-stitcher]

(from the checkout root: without PYTHONPATH the installed plenocli is measured instead).
"""

from __future__ import annotations

import argparse
import resource
import tracemalloc

import cv2
import numpy as np

from bench.timing import best_time
from plenocli.stitch import stitch
from plenocli.synth.rig import random_scene


def make_views(n_rows: int, n_cols: int, size: int, model: str, seed: int):
    """Views (V, size, size) float32 and the true view -> view 0 homographies."""
    rng = np.random.default_rng(seed)
    step = size * 0.7
    margin = 24
    scene = random_scene(seed=seed)
    corners = np.float32([[0, 0], [size - 1, 0], [size - 1, size - 1], [0, size - 1]])
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    vig = 1 - 0.1 * ((yy - size / 2) ** 2 + (xx - size / 2) ** 2) / (2 * (size / 2) ** 2)
    views, homs = [], []
    for k in range(n_rows * n_cols):
        i, j = divmod(k, n_cols)
        h = np.eye(3)
        h[:2, 2] = [margin + j * step, margin + i * step]
        if k:
            h[:2, 2] += rng.uniform(-3, 3, 2)
            if model == "homography":
                moved = corners + rng.uniform(-4, 4, (4, 2)).astype(np.float32)
                h = h @ cv2.getPerspectiveTransform(corners, moved).astype(np.float64)
        q = h @ np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size, np.float32)])
        view = scene(q[0] / q[2], q[1] / q[2]).reshape(size, size).astype(np.float32)
        gain = (1.0, 0.85, 1.1, 0.95)[k]
        views.append(gain * vig * view + rng.normal(0, 0.003, view.shape).astype(np.float32))
        homs.append(h)
    relative = [np.linalg.inv(homs[0]) @ h for h in homs]
    return np.stack(views).astype(np.float32), relative


def corner_error(truth: list[np.ndarray], report, size: int) -> float:
    corners = np.float64([[0, 0], [size - 1, 0], [size - 1, size - 1], [0, size - 1]])
    corners = corners.reshape(-1, 1, 2)
    return max(float(np.abs(cv2.perspectiveTransform(corners, t)
                            - cv2.perspectiveTransform(corners, np.asarray(e))).max())
               for t, e in zip(truth[1:], report.transform["view_to_reference"][1:],
                               strict=True))


def to_uint8(view: np.ndarray) -> np.ndarray:
    return np.clip(255 * view / 1.2, 0, 255).astype(np.uint8)


def run_case(name: str, layout: str, n_rows: int, n_cols: int, size: int, model: str,
             repeat: int, skip_stitcher: bool) -> None:
    views, truth = make_views(n_rows, n_cols, size, model, seed=1)
    t_ours, (pano, report) = best_time(lambda: stitch(views, layout=layout, model=model),
                                       repeat)
    tracemalloc.start()
    stitch(views, layout=layout, model=model)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    error = corner_error(truth, report, size)
    print(f"\n== {name}: {len(views)} views of {size} x {size}, layout {layout}, {model} ==")
    print(f"plenocli stitch      {t_ours:7.2f} s   panorama {pano.shape[1]} x {pano.shape[0]}, "
          f"corner error {error:.3f} px, numpy peak {traced_peak / 2**20:.0f} MiB, "
          f"process peak RSS {rss:.0f} MiB")
    if model == "translation":
        window = cv2.createHanningWindow((size, size), cv2.CV_64F)

        def phase():
            shifts = []
            for k in range(1, len(views)):
                (dx, dy), _ = cv2.phaseCorrelate(views[k].astype(np.float64),
                                                 views[0].astype(np.float64), window)
                # the shift is found modulo the view size: unwrap towards the layout position
                i, j = divmod(k, n_cols)
                dy += size * np.round((i * 0.7 * size - dy) / size)
                dx += size * np.round((j * 0.7 * size - dx) / size)
                shifts.append((dy, dx))
            return shifts

        t_base, shifts = best_time(phase, repeat)
        err = max(max(abs(dy - t[1, 2]), abs(dx - t[0, 2]))
                  for (dy, dx), t in zip(shifts, truth[1:], strict=True))
        print(f"cv2.phaseCorrelate   {t_base:7.2f} s   registration only, shift error "
              f"{err:.3f} px")
        print(f"ratio plenocli / phaseCorrelate = {t_ours / t_base:.1f} x (plenocli also "
              "matches gains and blends the panorama)")
        return
    if skip_stitcher:
        return
    stitcher = cv2.Stitcher_create(cv2.Stitcher_SCANS)
    images = [cv2.cvtColor(to_uint8(v), cv2.COLOR_GRAY2BGR) for v in views]
    t_base, (status, cv_pano) = best_time(lambda: stitcher.stitch(images), repeat)
    if status != cv2.Stitcher_OK:
        print(f"cv2.Stitcher SCANS   {t_base:7.2f} s   failed (status {status}): no baseline")
        return
    print(f"cv2.Stitcher SCANS   {t_base:7.2f} s   panorama {cv_pano.shape[1]} x "
          f"{cv_pano.shape[0]} (8-bit, its own resolution choice; no ground-truth check)")
    print(f"ratio plenocli / cv2.Stitcher = {t_ours / t_base:.2f} x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--skip-stitcher", action="store_true",
                        help="do not run the cv2.Stitcher baseline (slow on 3000 px views)")
    args = parser.parse_args()
    print(f"OpenCV {cv2.__version__}, threads {cv2.getNumThreads()}")
    for model in ("translation", "homography"):
        run_case("pair", "1x2", 1, 2, 3000, model, args.repeat, args.skip_stitcher)
        run_case("quad", "2x2", 2, 2, 1500, model, args.repeat, args.skip_stitcher)


if __name__ == "__main__":
    main()
