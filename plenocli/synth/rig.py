"""Synthetic multi-view rigs: a wide textured scene cut into 2 or 4 overlapping views.

Used to test ``plenocli.stitch`` (known translation or homography between views) and
``plenocli.crosstalk`` (white-target captures with a known cross-talk ratio r).

Geometry convention: view ``k`` pixel ``(x, y)`` (column, row) sees the scene at
``H_k @ (x, y, 1)`` (scene pixel coordinates, column first). For the translation model ``H_k`` is
a pure shift. Views are ordered row-major over the layout: ``1x2`` = left, right; ``2x1`` = top,
bottom; ``2x2`` = S00, S01, S10, S11 (top-left, top-right, bottom-left, bottom-right).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from plenocli.stitch.views import LAYOUTS, VIEW_NAMES
from plenocli.synth.capture import SimFile, Simulation


def make_scene(shape: tuple[int, int], *, seed: int = 0, blur_px: float = 1.5) -> np.ndarray:
    """A band-limited textured scene in [0.1, 1]: multi-scale noise plus smooth discs.

    Parameters
    ----------
    shape : (rows, cols) of the scene in pixels.
    seed : seed of ``np.random.default_rng``.
    blur_px : Gaussian sigma (px) applied last, so that sub-pixel resampling is accurate.

    Returns
    -------
    (rows, cols) float64 scene radiance.
    """
    rng = np.random.default_rng(seed)
    rows, cols = shape
    scene = np.zeros(shape)
    for sigma, amp in ((1.0, 0.25), (4.0, 0.5), (16.0, 1.0)):
        layer = ndimage.gaussian_filter(rng.standard_normal(shape), sigma)
        scene += amp * layer / layer.std()
    yy, xx = np.mgrid[0:rows, 0:cols]
    for _ in range(max(4, rows * cols // 20000)):
        cy, cx = rng.uniform(0, rows), rng.uniform(0, cols)
        rad = rng.uniform(5, 30)
        scene += rng.uniform(-1.5, 1.5) * ((yy - cy) ** 2 + (xx - cx) ** 2 < rad**2)
    scene = ndimage.gaussian_filter(scene, blur_px)
    lo, hi = scene.min(), scene.max()
    return 0.1 + 0.9 * (scene - lo) / (hi - lo)


def _view_homographies(layout: str, view_shape: tuple[int, int], overlap: float,
                       model: str, jitter_px: float, perspective_px: float,
                       rng: np.random.Generator) -> list[np.ndarray]:
    """Per-view 3x3 maps view pixel -> scene pixel, before the scene margin is added."""
    n_rows, n_cols = LAYOUTS[layout]
    rows, cols = view_shape
    corners = np.float32([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
    homographies = []
    for k in range(n_rows * n_cols):
        i, j = divmod(k, n_cols)
        shift = np.array([j * cols * (1 - overlap), i * rows * (1 - overlap)])
        if k:
            shift += rng.uniform(-jitter_px, jitter_px, 2)
        h = np.eye(3)
        h[:2, 2] = shift
        if model == "homography" and k:
            moved = corners + rng.uniform(-perspective_px, perspective_px, (4, 2)).astype(
                np.float32)
            h = h @ cv2.getPerspectiveTransform(corners, moved).astype(np.float64)
        homographies.append(h)
    return homographies


def make_rig(*, layout: str = "1x2", view_shape: tuple[int, int] = (240, 320),
             overlap: float = 0.25, model: str = "translation", jitter_px: float = 3.0,
             perspective_px: float = 6.0, gains: tuple[float, ...] | None = None,
             vignetting: float = 0.0, noise: float = 0.0, ghost_r: float = 0.0,
             seed: int = 0) -> tuple[np.ndarray, np.ndarray, dict]:
    """Cut a synthetic scene into overlapping views with known geometry and photometry.

    Parameters
    ----------
    layout : "1x2", "2x1" or "2x2" (views row-major over the layout).
    view_shape : (rows, cols) of every view in pixels.
    overlap : nominal overlap between neighbouring views, fraction of the view size.
    model : "translation" (pure sub-pixel shifts) or "homography" (plus a random perspective
        distortion of up to ``perspective_px`` at each corner of views 1..).
    jitter_px : random sub-pixel offset (+- px) added to the nominal position of views 1...
    gains : per-view gain (default 1 for view 0, then 0.85, 1.1, 0.95).
    vignetting : radial fall-off strength: view * (1 - vignetting * (r / r_corner)^2).
    noise : standard deviation of additive Gaussian noise (scene units).
    ghost_r : cross-talk: each view gets ``ghost_r`` times its neighbour view added (before noise).
    seed : seed of ``np.random.default_rng``.

    Returns
    -------
    views : (V, rows, cols) float32 observed views.
    clean : (V, rows, cols) float32 views with gain 1, no vignetting, noise or ghost.
    truth : dict with ``homographies`` (view -> scene), ``relative`` (view k -> view 0 pixel
        coordinates), ``shifts_px`` ([dy, dx] of view k in view 0 coordinates, translation model),
        ``scene`` (the full scene array, not JSON) and ``scene_origin`` (scene pixel of view 0's
        (0, 0)), gains, vignetting, noise, ghost_r.
    """
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {sorted(LAYOUTS)}, got {layout!r}")
    if model not in ("translation", "homography"):
        raise ValueError(f"model must be 'translation' or 'homography', got {model!r}")
    if not 0.0 <= overlap < 1.0:
        raise ValueError(f"overlap must be in [0, 1), got {overlap}")
    rng = np.random.default_rng(seed)
    rows, cols = view_shape
    n_views = LAYOUTS[layout][0] * LAYOUTS[layout][1]
    homs = _view_homographies(layout, view_shape, overlap, model, jitter_px, perspective_px, rng)
    margin = int(np.ceil(jitter_px + perspective_px + 16))
    origin = np.eye(3)
    origin[:2, 2] = margin
    homs = [origin @ h for h in homs]
    n_rows, n_cols = LAYOUTS[layout]
    scene_shape = (int(rows * (1 + (n_rows - 1) * (1 - overlap))) + 2 * margin,
                   int(cols * (1 + (n_cols - 1) * (1 - overlap))) + 2 * margin)
    scene = make_scene(scene_shape, seed=seed)
    coeffs = ndimage.spline_filter(scene, order=3)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    pts = np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size)])
    clean = np.empty((n_views, rows, cols), np.float32)
    for k, h in enumerate(homs):
        q = h @ pts
        sx, sy = q[0] / q[2], q[1] / q[2]
        clean[k] = ndimage.map_coordinates(coeffs, [sy, sx], order=3, prefilter=False,
                                           mode="nearest").reshape(rows, cols)
    gains = tuple(gains) if gains is not None else (1.0, 0.85, 1.1, 0.95)[:n_views]
    if len(gains) != n_views:
        raise ValueError(f"gains must have {n_views} values for layout {layout}, got {len(gains)}")
    radius2 = ((yy - (rows - 1) / 2) ** 2 + (xx - (cols - 1) / 2) ** 2)
    vig = 1.0 - vignetting * radius2 / radius2.max()
    views = np.stack([g * vig * v for g, v in zip(gains, clean, strict=True)])
    if ghost_r:
        partner = [k ^ 1 for k in range(n_views)]  # the horizontal (or only) neighbour
        views = views + ghost_r * views[partner]
    if noise:
        views = views + rng.normal(0.0, noise, views.shape)
    inv0 = np.linalg.inv(homs[0])
    relative = [inv0 @ h for h in homs]
    truth = {
        "layout": layout, "model": model, "view_shape": [rows, cols], "overlap": overlap,
        "view_names": list(VIEW_NAMES[layout]),
        "homographies": [h.tolist() for h in homs],
        "relative": [(r / r[2, 2]).tolist() for r in relative],
        "shifts_px": [[r[1, 2], r[0, 2]] for r in relative],
        "gains": list(gains), "vignetting": vignetting, "noise": noise, "ghost_r": ghost_r,
        "scene_origin": [margin, margin], "scene": scene, "seed": seed,
    }
    return views.astype(np.float32), clean, truth


def make_masked_white(*, view_shape: tuple[int, int] = (120, 160), n_views: int = 2,
                      intended: int = 0, r: float | tuple[float, ...] = 0.13,
                      r_slope: float = 0.0, cfa: str | None = None,
                      r_per_colour: dict[str, float] | None = None, level: float = 1000.0,
                      vignetting: float = 0.3, noise: float = 0.0,
                      seed: int = 0) -> tuple[np.ndarray, dict]:
    """Views of a white target with all but one pupil part masked: a known cross-talk ratio.

    View ``intended`` receives ``level * vignetting``; every other view ``k`` receives
    ``r_k(x) * intended`` with ``r_k(x) = r_k + r_slope * (x / (cols - 1) - 0.5)`` (cross-talk
    that varies across the frame), times ``r_per_colour[c] / r_0`` on a Bayer ``cfa``.

    Returns
    -------
    views : (n_views, rows, cols) float32.
    truth : dict with ``r`` (the true global ratio, computed from the noise-free arrays as
        max_k sum(view_k) / sum(view_intended)), ``r_per_view`` and ``r_per_colour``.
    """
    if not 0 <= intended < n_views:
        raise ValueError(f"intended must be in [0, {n_views}), got {intended}")
    rng = np.random.default_rng(seed)
    rows, cols = view_shape
    rs = (r,) * (n_views - 1) if np.isscalar(r) else tuple(r)
    if len(rs) != n_views - 1:
        raise ValueError(f"r needs {n_views - 1} values (one per other view), got {len(rs)}")
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    radius2 = (yy - rows / 2) ** 2 + (xx - cols / 2) ** 2
    main = level * (1.0 - vignetting * radius2 / radius2.max())
    colour_scale = np.ones((rows, cols))
    if cfa and r_per_colour:
        ref = r_per_colour.get("G", 1.0)
        for k, colour in enumerate(cfa.upper()):
            colour_scale[k // 2::2, k % 2::2] = r_per_colour[colour] / ref
    views = np.zeros((n_views, rows, cols))
    views[intended] = main
    others = [k for k in range(n_views) if k != intended]
    for k, rk in zip(others, rs, strict=True):
        views[k] = main * colour_scale * (rk + r_slope * (xx / (cols - 1) - 0.5))
    per_view = {k: float(views[k].sum() / main.sum()) for k in others}
    per_colour = {}
    if cfa:
        for colour in sorted(set(cfa.upper())):
            sel = np.zeros((rows, cols), bool)
            for k, c in enumerate(cfa.upper()):
                if c == colour:
                    sel[k // 2::2, k % 2::2] = True
            per_colour[colour] = max(float(views[k][sel].sum() / main[sel].sum())
                                     for k in others)
    truth = {"r": max(per_view.values()), "r_per_view": per_view, "r_per_colour": per_colour,
             "intended": intended, "cfa": cfa}
    if noise:
        views = views + rng.normal(0.0, noise, views.shape)
    return views.astype(np.float32), truth


def _simulate_rig(layout: str, *, seed: int, view_shape, overlap: float, model: str,
                  noise: float, ghost_r: float, vignetting: float) -> Simulation:
    views, _, truth = make_rig(layout=layout, view_shape=tuple(view_shape), overlap=overlap,
                               model=model, noise=noise, ghost_r=ghost_r, vignetting=vignetting,
                               seed=seed)
    names = truth["view_names"]
    meta = {"views": names, "cfa": None}
    files = [SimFile("views.tif", views, "image", {"meta": meta})]
    for k, name in enumerate(names):  # one masked white capture per view (cross-talk target)
        white, wtruth = make_masked_white(view_shape=tuple(view_shape), n_views=len(names),
                                          intended=k, r=0.05 + ghost_r, noise=noise,
                                          seed=seed + 1 + k)
        files.append(SimFile(f"white_{name}.tif", white, "image", {"meta": meta}))
        truth.setdefault("crosstalk", {})[name] = wtruth["r"]
    public = {k: v for k, v in truth.items() if k != "scene"}
    public.update(files={f.name[:-4]: f.name for f in files},
                  kind=f"{'quad' if layout == '2x2' else 'stereo'}-rig")
    return Simulation(tuple(files), public)


def simulate_stereo_rig(*, seed: int = 0, view_shape: tuple[int, int] = (400, 500),
                        overlap: float = 0.2, model: str = "translation", noise: float = 0.002,
                        ghost_r: float = 0.0, vignetting: float = 0.2) -> Simulation:
    """A two-view rig: views.tif (L, R), white_L.tif, white_R.tif and the truth."""
    return _simulate_rig("1x2", seed=seed, view_shape=view_shape, overlap=overlap, model=model,
                         noise=noise, ghost_r=ghost_r, vignetting=vignetting)


def simulate_quad_rig(*, seed: int = 0, view_shape: tuple[int, int] = (300, 400),
                      overlap: float = 0.2, model: str = "translation", noise: float = 0.002,
                      ghost_r: float = 0.0, vignetting: float = 0.2) -> Simulation:
    """A 2 x 2 rig: views S00, S01, S10, S11 + one masked white per view, and the truth."""
    return _simulate_rig("2x2", seed=seed, view_shape=view_shape, overlap=overlap, model=model,
                         noise=noise, ghost_r=ghost_r, vignetting=vignetting)
