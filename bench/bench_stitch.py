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
  skipped with a note when OpenCV cannot stitch the views. Its far-corner error is read from
  its cameras (affine maps at its registration scale).
Times are the best of ``--repeat`` runs (end to end: registration + gains + blending for
plenocli), CPU times (all threads) the mean. Memory: tracemalloc peak of numpy allocations
during one plenocli run and the process peak RSS (ru_maxrss) after it. Errors are against the
known geometry: shift error (px) and the far-corner error of the homography (px).

Sharpness (``--baseline COMMIT``): the same analytic scene seen through the demo's dual-pixel
prism rig (each view pixel evaluated at the common-frame point the rig's ray model sends it to),
stitched with the rig by this checkout and by the baseline commit (its own process); printed:
the RMS error of each panorama against the scene evaluated at every panorama pixel (pixels
both cover, 8 px from the edges), so a resampling fewer shows as a smaller error.

    PYTHONPATH=. python bench/bench_stitch.py [--repeat 1] [--skip-stitcher] [--baseline e6b5602]
        [--case pair|quad] [--model translation|homography]

(from the checkout root: without PYTHONPATH the installed plenocli is measured instead).
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
import tracemalloc
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from bench.timing import ROOT, best_time, export_package, run_python
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


def stitcher_corner_error(stitcher, truth: list[np.ndarray], size: int) -> float:
    """The far-corner error (px) of cv2.Stitcher's view -> view 0 maps: its cameras' ``R`` are
    the affine maps reference -> view at its registration scale (``workScale``)."""
    s = stitcher.workScale()
    scale = np.array([[s, 0, 0.5 * s - 0.5], [0, s, 0.5 * s - 0.5], [0, 0, 1]])
    cams = [np.asarray(c.R, np.float64) for c in stitcher.cameras()]
    estimate = [np.linalg.inv(scale) @ cams[0] @ np.linalg.inv(r) @ scale for r in cams]
    report = type("Report", (), {"transform": {"view_to_reference": estimate}})
    return corner_error(truth, report, size)


def to_uint8(view: np.ndarray) -> np.ndarray:
    return np.clip(255 * view / 1.2, 0, 255).astype(np.uint8)


def run_case(name: str, layout: str, n_rows: int, n_cols: int, size: int, model: str,
             repeat: int, skip_stitcher: bool) -> None:
    views, truth = make_views(n_rows, n_cols, size, model, seed=1)
    cpu = time.process_time()
    t_ours, (pano, report) = best_time(lambda: stitch(views, layout=layout, model=model),
                                       repeat)
    cpu_ours = (time.process_time() - cpu) / repeat
    tracemalloc.start()
    stitch(views, layout=layout, model=model)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    error = corner_error(truth, report, size)
    print(f"\n== {name}: {len(views)} views of {size} x {size}, layout {layout}, {model} ==")
    print(f"plenocli stitch      {t_ours:7.2f} s   (CPU {cpu_ours:.2f} s) panorama "
          f"{pano.shape[1]} x {pano.shape[0]}, corner error {error:.3f} px, numpy peak "
          f"{traced_peak / 2**20:.0f} MiB, "
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
    cpu = time.process_time()
    t_base, (status, cv_pano) = best_time(lambda: stitcher.stitch(images), repeat)
    cpu_base = (time.process_time() - cpu) / repeat
    if status != cv2.Stitcher_OK:
        print(f"cv2.Stitcher SCANS   {t_base:7.2f} s   failed (status {status}): no baseline")
        return
    print(f"cv2.Stitcher SCANS   {t_base:7.2f} s   (CPU {cpu_base:.2f} s) panorama "
          f"{cv_pano.shape[1]} x {cv_pano.shape[0]} (8-bit, affine), corner error "
          f"{stitcher_corner_error(stitcher, truth, size):.2f} px")
    print(f"ratio plenocli / cv2.Stitcher = {t_ours / t_base:.2f} x "
          f"(CPU {cpu_ours / cpu_base:.2f} x)")


SHARP_RUNNER = """
import json, sys, time
import numpy as np
try:
    from plenocli.io.rigfile import read_rig as load_rig
except ImportError:  # a baseline commit from before the rig file moved to io/
    from plenocli.pipeline.stages.stitch import load_rig
from plenocli.stitch import stitch
start = time.perf_counter()
pano, rep = stitch(np.load(sys.argv[1]), layout=sys.argv[4], rig=load_rig(sys.argv[2]))
seconds = time.perf_counter() - start
np.save(sys.argv[3], pano)
print(json.dumps({"seconds": seconds, "origin": rep.origin_px, "canvas": rep.canvas_origins_px,
                  "shifts": rep.shifts_px}))
"""


def sharpness(baseline: str, rig_name: str, layout: str, pixels: int) -> None:
    """Error against the analytic scene of the rig's panorama, this checkout vs ``baseline``."""
    from plenocli.io.rigfile import read_rig as load_rig
    from plenocli.stitch import view_to_common

    rig_file = ROOT / "configs" / "rigs" / f"{rig_name}.yaml"
    rig = load_rig(str(rig_file))
    scene = random_scene(seed=5, min_period_px=8.0)
    shape = (pixels if layout == "2x2" else pixels * 2 // 3, pixels)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    # views 1.. see the scene moved by a fraction of a pixel (the rig model's error, which the
    # registration measures): their pixels land between the panorama's
    offsets = ((0.0, 0.0), (0.37, 0.41), (-0.29, 0.33), (0.45, -0.21))[:len(rig.views)]
    views = np.stack([scene(*(c + d for c, d in zip(view_to_common(rig, k, xx, yy, shape),
                                                    offset, strict=True)))
                      for k, offset in enumerate(offsets)])
    print(f"\n== sharpness: {rig_name} rig, {len(views)} views {shape[1]} x {shape[0]}, analytic "
          "scene (periods >= 8 px: no aliasing through the prisms), views 1.. 0.3-0.5 px off ==")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        np.save(folder / "views.npy", views.astype(np.float32))
        export_package(baseline, folder)
        results = []
        for name, root in ((f"baseline {baseline}", folder), ("this checkout", ROOT)):
            out = folder / f"pano{len(results)}.npy"
            rep = json.loads(run_python(SHARP_RUNNER, str(folder / "views.npy"), str(rig_file),
                                        str(out), layout, root=root).strip().splitlines()[-1])
            pano = np.load(out)
            rr, cc = np.mgrid[0:pano.shape[0], 0:pano.shape[1]].astype(np.float64)
            truth = scene(cc - rep["origin"][1] + rep["canvas"][0][1],
                          rr - rep["origin"][0] + rep["canvas"][0][0])
            results.append((name, rep, pano, truth))
        for name, rep, pano, truth in results:
            ok = ndimage.binary_erosion(np.isfinite(pano), iterations=8)
            err = np.where(ok, pano - truth, np.nan)
            thirds = [np.sqrt(np.nanmean(part**2)) for part in np.array_split(err, 3, axis=1)]
            print(f"{name:22s} {rep['seconds']:6.2f} s   RMS error vs the scene "
                  f"{np.sqrt(np.nanmean(err**2)):.5f} (left, middle, right third "
                  f"{', '.join(f'{t:.5f}' for t in thirds)}; scene std {truth[ok].std():.3f}), "
                  f"shift {rep['shifts'][1][0]:.4f}, {rep['shifts'][1][1]:.4f} px")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--skip-stitcher", action="store_true",
                        help="do not run the cv2.Stitcher baseline (slow on 3000 px views)")
    parser.add_argument("--baseline", default=None,
                        help="git commit to compare the rig panorama's sharpness with")
    parser.add_argument("--only-sharpness", action="store_true")
    parser.add_argument("--case", choices=["pair", "quad"], default=None,
                        help="run only this case (both models)")
    parser.add_argument("--model", choices=["translation", "homography"], default=None,
                        help="run only this model")
    args = parser.parse_args()
    print(f"OpenCV {cv2.__version__}, threads {cv2.getNumThreads()}")
    if args.baseline:
        sharpness(args.baseline, "quadpixel_pyramid", "2x2", 768)
        sharpness(args.baseline, "dualpixel_prism", "1x2", 1536)
    if args.only_sharpness:
        return
    for model in ("translation", "homography"):
        for name, layout, n_rows, n_cols, size in (("pair", "1x2", 1, 2, 3000),
                                                   ("quad", "2x2", 2, 2, 1500)):
            if args.case in (None, name) and args.model in (None, model):
                run_case(name, layout, n_rows, n_cols, size, model, args.repeat,
                         args.skip_stitcher)


if __name__ == "__main__":
    main()
