"""Disparity between the views of a dual-pixel (A/B) or quad-pixel (2 x 2 SAIs) capture.

The disparity d is the shift of B's content against A's along the baseline, in pixels, + when
B's content lies to the right of A's (quad-pixel: the right column S01, S11 against the left
one, and the bottom row S10, S11 against the top one, + downwards). Steps (docs/depth.md):

1. Photometry: each view is divided by its own low-pass (Gaussian, sigma ``FLAT_SIGMA`` px), so
   what is left of the vignetting and of the A/B split after ``plenocli flat`` (or without it)
   does not bias the match; then both are smoothed by a small Gaussian.
2. Coarse: the windowed sum of squared differences of A(x) and B(x + d) for whole-pixel d in
   [-max, max], parabola through the minimum.
3. Refinement: Lucas-Kanade steps with symmetric warps (A moved by -d/2, B by +d/2, cubic
   interpolation), the gradient the mean of both: the asymmetric half-pupil blur of the two
   views (mirror images of each other) enters both sides alike instead of biasing one.
4. Confidence: 1 - best / median cost of the coarse curve (0 on textureless areas).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

FLAT_SIGMA = 24.0
PRE_BLUR = 1.0
WINDOW = 15
LK_STEPS = 3


@dataclass(frozen=True)
class Disparity:
    """Disparity (rows, cols) float32 px (NaN: unknown) and confidence (0..1)."""

    disparity: np.ndarray
    confidence: np.ndarray


def _prepare(view: np.ndarray) -> np.ndarray:
    v = np.asarray(view, np.float32)
    valid = np.isfinite(v)
    v = np.where(valid, v, 0.0).astype(np.float32)
    low = cv2.GaussianBlur(v, (0, 0), FLAT_SIGMA)
    cover = cv2.GaussianBlur(valid.astype(np.float32), (0, 0), FLAT_SIGMA)
    level = low / np.maximum(cover, 1e-6)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(valid & (level > 0), v / level, 0.0).astype(np.float32)
    return cv2.GaussianBlur(out, (0, 0), PRE_BLUR)


def _shift_x(img: np.ndarray, dx) -> np.ndarray:
    """img sampled at (x + dx, y) (dx a number or a map), cubic, border replicated."""
    rows, cols = img.shape
    grid_x = np.arange(cols, dtype=np.float32)[None, :] + np.asarray(dx, np.float32)
    grid_x = np.broadcast_to(grid_x, (rows, cols)).astype(np.float32)
    grid_y = np.broadcast_to(np.arange(rows, dtype=np.float32)[:, None], (rows, cols))
    return cv2.remap(img, grid_x, np.ascontiguousarray(grid_y), cv2.INTER_CUBIC,
                     borderMode=cv2.BORDER_REPLICATE)


def _box(img: np.ndarray) -> np.ndarray:
    return cv2.boxFilter(img, -1, (WINDOW, WINDOW), normalize=True,
                         borderType=cv2.BORDER_REFLECT)


def disparity_x(a: np.ndarray, b: np.ndarray, *, max_disparity: float = 4.0) -> Disparity:
    """Horizontal disparity of ``b`` against ``a`` (same shape, 2-D, NaN = no data)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"views must be two 2-D images of one shape, got {a.shape}, {b.shape}")
    if min(a.shape) < 2 * WINDOW:
        raise ValueError(f"views of {a.shape[1]} x {a.shape[0]} px are too small for "
                         f"{WINDOW} px windows")
    if not (np.isfinite(max_disparity) and 0.5 <= max_disparity <= 64):
        raise ValueError(f"max_disparity must be 0.5 to 64 px, got {max_disparity}")
    missing = ~(np.isfinite(a) & np.isfinite(b))
    pa, pb = _prepare(a), _prepare(b)
    shifts = np.arange(-int(np.ceil(max_disparity)), int(np.ceil(max_disparity)) + 1)
    costs = np.stack([_box((pa - _shift_x(pb, float(d))) ** 2) for d in shifts])
    k = np.argmin(costs, axis=0)
    best = np.take_along_axis(costs, k[None], 0)[0]
    cm = np.take_along_axis(costs, np.clip(k - 1, 0, len(shifts) - 1)[None], 0)[0]
    cp = np.take_along_axis(costs, np.clip(k + 1, 0, len(shifts) - 1)[None], 0)[0]
    curv = cm - 2 * best + cp
    inner = (k > 0) & (k < len(shifts) - 1) & (curv > 0)
    frac = np.where(inner, 0.5 * (cm - cp) / np.where(curv > 0, curv, 1), 0.0)
    d = (shifts[k] + np.clip(frac, -0.5, 0.5)).astype(np.float32)
    median = np.median(costs, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        conf = np.clip(1.0 - best / median, 0.0, 1.0)
    del costs
    d = _refine(pa, pb, d, float(shifts[-1]))
    conf = np.where(np.isfinite(conf), conf, 0.0).astype(np.float32)
    lost = cv2.dilate(missing.astype(np.uint8), np.ones((WINDOW, WINDOW), np.uint8)) > 0
    d[lost] = np.nan
    conf[lost] = 0.0
    return Disparity(d, conf)


def _refine(pa: np.ndarray, pb: np.ndarray, d: np.ndarray, limit: float) -> np.ndarray:
    """Lucas-Kanade steps on d with symmetric warps (A at x - d/2, B at x + d/2)."""
    for _ in range(LK_STEPS):
        wa = _shift_x(pa, -0.5 * d)
        wb = _shift_x(pb, 0.5 * d)
        grad = 0.5 * (np.gradient(wa, axis=1) + np.gradient(wb, axis=1))
        num = _box((wb - wa) * grad)
        den = _box(grad * grad)
        step = np.where(den > 1e-12, -num / np.maximum(den, 1e-12), 0.0)
        d = np.clip(d + np.clip(step, -0.5, 0.5), -limit, limit).astype(np.float32)
    return d


def quad_disparity(views: np.ndarray, *, max_disparity: float = 4.0
                   ) -> tuple[Disparity, Disparity]:
    """(x, y) disparities of 2 x 2 SAIs (S00, S01, S10, S11): right column against left,
    bottom row against top."""
    s00, s01, s10, s11 = (np.asarray(v, np.float32) for v in views)
    dx = disparity_x(0.5 * (s00 + s10), 0.5 * (s01 + s11), max_disparity=max_disparity)
    dy = disparity_x((0.5 * (s00 + s01)).T, (0.5 * (s10 + s11)).T, max_disparity=max_disparity)
    return dx, Disparity(np.ascontiguousarray(dy.disparity.T),
                         np.ascontiguousarray(dy.confidence.T))
