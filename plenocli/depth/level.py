"""The slow level a dual- or quad-pixel view is divided by before it is matched
(``plenocli.depth.views``, step 1): the geometric mean over a wide Gaussian, taken through
holes (NaN pixels) filled continuously."""

from __future__ import annotations

import cv2
import numpy as np

FLAT_SIGMA = 24.0
FLAT_SHRINK = 8
LOG_FLOOR = 0.02  # of a view's median: the darkest level its log low-pass takes (level)


def level(v: np.ndarray, data: np.ndarray) -> np.ndarray:
    """The view's slow level: the geometric mean over a Gaussian of sigma FLAT_SIGMA (the
    exponential of the low-pass of its log), over the pixels with data.
    Of the log, not of the view: a gain is a factor. A view g t (g slow) has log g + log t,
    whose low-pass is log g + LP(log t) wherever log g is linear within the Gaussian, so g
    comes out whatever the scene; the low-pass of g t itself is g LP(t) + sigma^2 g' LP(t)',
    a few % of the level where the scene's own low-pass slopes, which a slow gain ramp (the
    A/S split) leaves as an offset between the views that moves the match: opposite ramps
    across A and B put 1.4-12 % of natural pictures' known pixels > 1 px off at confidence
    0.93 (audit 18 W5). Pixels darker than LOG_FLOOR of the view's median (noise about the
    black level) count as that floor here only.
    Pixels without data take, in the log, a fill continuous with the data around them
    (``_fill``) before the low-pass. Left out of the low-pass instead, a hole's edge cut its
    Gaussian: the views' levels then differ by the disparity times the log contrast at the
    edge (the cut does not move with the content), a few % within 72 px of the hole, which
    in faint texture is a match off by pixels; a fill that meets the edge's values leaves
    only the disparity times their gradient (a 60 x 80 px NaN block of a natural picture at
    0.5-1.9 px: 0.0-0.6 % of the known pixels > 1 px off, 27-28 % before; audit 21 W2)."""
    sample = v[::7, ::7][data[::7, ::7]]
    typical = float(np.median(sample)) if sample.size else 0.0
    if not typical > 0:
        typical = float(np.max(np.abs(sample))) if sample.size else 1.0
    logs = np.where(data, np.log(np.maximum(v, LOG_FLOOR * max(typical, 1e-30))), 0.0)
    logs = logs.astype(np.float32)
    if not data.all():
        logs = _fill(logs, data.astype(np.float32))
    return np.exp(_low_pass(logs))


def _fill(img: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``img`` where ``weight`` is 1, elsewhere (0) filled by push-pull: each pixel without
    data takes the next coarser level's value (halved by area over the pixels with data,
    itself filled so, a cell counted whole from a quarter of data), interpolated back, so
    the fill meets the data at a hole's edge and runs smoothly across it. O(pixels)."""
    rows, cols = img.shape
    if weight.min() > 0.999:
        return img
    if min(rows, cols) <= 2:  # the coarsest level: what has no data takes the mean
        total = float(weight.sum())
        mean = float((img * weight).sum()) / total if total > 0 else 0.0
        return (img * weight + mean * (1 - weight)).astype(np.float32)
    size = ((cols + 1) // 2, (rows + 1) // 2)
    num = cv2.resize(img * weight, size, interpolation=cv2.INTER_AREA)
    den = cv2.resize(weight, size, interpolation=cv2.INTER_AREA)
    coarse = _fill(np.where(den > 1e-6, num / np.maximum(den, 1e-6), 0.0).astype(np.float32),
                   np.minimum(1.0, 4 * den).astype(np.float32))
    up = cv2.resize(coarse, (cols, rows), interpolation=cv2.INTER_LINEAR)
    return (img * weight + up * (1 - weight)).astype(np.float32)


def _extend(img: np.ndarray, pad: int, band: int) -> np.ndarray:
    """``img`` extended by ``pad`` columns either side, each row along the straight line
    fitted (least squares) to its ``band`` columns nearest that edge: a ramp stays a ramp,
    and the line is not swayed by the one column at the edge as an odd reflection about it
    is (a view's edge column holds what the other view does not see)."""
    band = min(band, img.shape[1])
    if band < 2:
        return np.pad(img, ((0, 0), (pad, pad)), mode="edge")
    x = np.arange(band, dtype=np.float64) - (band - 1) / 2
    steps = np.arange(1, pad + 1, dtype=np.float64)
    sides = []
    for part, outward in ((img[:, :band], -1.0), (img[:, -band:], 1.0)):
        mean = part.mean(axis=1, keepdims=True)
        slope = ((part - mean) * x).sum(axis=1, keepdims=True) / (x * x).sum()
        edge = (band - 1) / 2
        sides.append(mean + slope * outward * (edge + steps[None, :]))
    return np.concatenate([sides[0][:, ::-1], img, sides[1]], axis=1)


def _low_pass(img: np.ndarray) -> np.ndarray:
    """Gaussian of sigma FLAT_SIGMA of ``img`` (every pixel with data: ``_fill``), computed on
    an image shrunk by FLAT_SHRINK (the result is smooth on that scale, so nothing is lost,
    and 30 Mpx take a fraction of a second). Past the frame's edges the shrunk image is
    extended along lines (``_extend``), which keeps a linear field linear: a reflection
    folds a gain ramp back at the edges, and the views' opposite ramps then differed within
    48 px of the left and right edges (most of the pixels still > 1 px off after the log)."""
    rows, cols = img.shape
    size = (max(1, cols // FLAT_SHRINK), max(1, rows // FLAT_SHRINK))
    small = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    sigma = FLAT_SIGMA / FLAT_SHRINK
    pad = int(np.ceil(3 * sigma))
    # the line through about one sigma of cells (4, 32 px): over 9 cells (72 px) the scene's
    # own curvature bent it (2-4 % of a natural picture's known pixels > 1 px off, 0 at 4);
    # an odd reflection about the edge cell put 0.6 % of a periodic texture's wrong
    band = int(np.ceil(sigma)) + 1
    big = _extend(_extend(small, pad, band).T, pad, band).T
    small = cv2.GaussianBlur(np.ascontiguousarray(big, np.float32), (0, 0), sigma,
                             borderType=cv2.BORDER_REFLECT)[pad:-pad, pad:-pad]
    return cv2.resize(np.ascontiguousarray(small), (cols, rows),
                      interpolation=cv2.INTER_LINEAR)
