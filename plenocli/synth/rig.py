"""Synthetic multi-view rigs: a wide textured scene cut into 2 or 4 overlapping views.

Used to test ``plenocli.stitch`` (known translation or homography between views) and
``plenocli.crosstalk`` (white-target captures with a known cross-talk ratio r).

Geometry convention: view ``k`` pixel ``(x, y)`` (column, row) sees the scene at
``H_k @ (x, y, 1)`` (scene pixel coordinates, column first). For the translation model ``H_k`` is
a pure shift. Views are ordered row-major over the layout: ``1x2`` = left, right; ``2x1`` = top,
bottom; ``2x2`` = S00, S01, S10, S11 (top-left, top-right, bottom-left, bottom-right).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np

from plenocli.stitch.views import LAYOUTS, VIEW_NAMES
from plenocli.synth.capture import SimFile, Simulation


@dataclass(frozen=True)
class CosineScene:
    """An analytic, band-limited scene: ``0.55 + 0.15 * sum_k a_k cos(2 pi f_k . (x, y) + phi_k)
    / std``, clipped to [0.1, 1], defined at any real (x, y) (px, column first).

    Views are rendered by evaluating it at their warped pixel coordinates, so the ground truth
    owes nothing to a resampler (in particular not to the cubic splines the photometric
    refinement of :mod:`plenocli.stitch` uses).
    """

    frequencies: np.ndarray  # (K, 2) cycles/px, (fx, fy)
    phases: np.ndarray  # (K,) rad
    amplitudes: np.ndarray  # (K,)

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Scene values at (x, y) (any equal shapes), float64."""
        xf = np.ascontiguousarray(x, np.float64).ravel()
        yf = np.ascontiguousarray(y, np.float64).ravel()
        w = 2 * np.pi * self.frequencies
        out = np.empty(xf.size)
        _sum_of_cosines(xf, yf, np.ascontiguousarray(w[:, 0]), np.ascontiguousarray(w[:, 1]),
                        self.phases, self.amplitudes, out)
        std = np.sqrt(0.5 * np.sum(self.amplitudes**2))
        return np.clip(0.55 + 0.15 * out / std, 0.1, 1.0).reshape(np.shape(x))


@numba.njit(cache=True)
def _sum_of_cosines(x, y, wx, wy, phase, amplitude, out):
    """out[i] = sum_k amplitude[k] cos(wx[k] x[i] + wy[k] y[i] + phase[k]) (numba: numpy's
    (points, components) temporaries were twice as slow)."""
    for i in range(x.size):
        acc = 0.0
        for k in range(wx.size):
            acc += amplitude[k] * math.cos(wx[k] * x[i] + wy[k] * y[i] + phase[k])
        out[i] = acc


def random_scene(*, seed: int = 0, components: int = 64, min_period_px: float = 3.0,
                 max_period_px: float = 60.0) -> CosineScene:
    """A seeded :class:`CosineScene`: ``components`` cosines in random directions with periods
    log-uniform in [``min_period_px``, ``max_period_px``] (below the Nyquist limit of 2 px) and
    amplitudes growing as sqrt(period), a texture with structure at every scale and no period
    (so a registration has one true match)."""
    if not 2 < min_period_px < max_period_px:
        raise ValueError(f"periods must satisfy 2 < min_period_px < max_period_px, got "
                         f"{min_period_px}, {max_period_px}")
    rng = np.random.default_rng(seed)
    period = np.exp(rng.uniform(np.log(min_period_px), np.log(max_period_px), components))
    angle = rng.uniform(0, np.pi, components)
    freq = np.stack([np.cos(angle), np.sin(angle)], axis=1) / period[:, None]
    return CosineScene(freq, rng.uniform(0, 2 * np.pi, components), np.sqrt(period))


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
        shift = np.array([j * cols * (1 - overlap), i * rows * (1 - overlap)], dtype=float)
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
        ``scene`` (the analytic :class:`CosineScene`, not JSON) and ``scene_origin`` (scene pixel of
        view 0's (0, 0)), gains, vignetting, noise, ghost_r.
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
    scene = random_scene(seed=seed)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    pts = np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size)])
    clean = np.empty((n_views, rows, cols), np.float32)
    for k, h in enumerate(homs):
        q = h @ pts
        clean[k] = scene(q[0] / q[2], q[1] / q[2]).reshape(rows, cols)
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
    if len(view_shape) != 2 or min(view_shape) < 32:
        raise ValueError(f"view_shape must be [ROWS, COLS], each at least 32, got "
                         f"{list(view_shape)}")
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
