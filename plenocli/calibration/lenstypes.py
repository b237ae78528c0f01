"""Lens types of a multi-focus array: three micro-lens focal lengths interleaved on the hex
lattice, each type on one coset of the index-3 sub-lattice ((i - j) mod 3). At a given depth
the types image the scene with different sharpness, so the cosets differ in the high-frequency
energy of their micro-images while lenses of one coset agree.

Which coset is which type is a matter of depth, not of sharpness in one frame: Raytrix's type 0
is focused on the near virtual depths (small g, e.g. 1-3.2), type 2 on the far ones. So each
coset's sharpness relative to its neighbours is compared between the near and the far third of
the virtual depths g of the frame's lenses (:func:`plenocli.depth.lenslet.lens_depth`): the
coset whose relative sharpness falls most from near to far is type 0, the one whose sharpness
rises most type 2. When the frame's depths do not separate them (a flat scene, too little
detail), no types are given."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np
from scipy import special

SIGNIFICANCE = 1e-6   # a one-way ANOVA p-value below this: the cosets differ in sharpness
SLOPE_SEPARATION = 4.0  # changes of types 0 and 2 this many standard errors apart decide
MIN_DEPTH_SPREAD = 0.5  # interquartile range of g (virtual depth) a frame needs to decide
CLEAR_MATCH = 0.5       # median lens confidence at which one sign of g is taken at once
# Lens types need each lens's g only roughly: the frame is matched at most at this pitch, so the
# cost follows the number of lenses, not of pixels (g is a ratio of shifts: scale-free).
DEPTH_PITCH_PX = 24.0


@dataclass(frozen=True)
class LensTypes:
    """Type (0 = focused nearest in virtual depth) of every lens, the median sharpness of each
    type relative to its neighbours, the ANOVA p-value of the difference, and each type's
    change of log relative sharpness from near to far g."""

    types: np.ndarray          # (K,) int8
    sharpness: tuple[float, float, float]
    p_value: float
    change: tuple[float, float, float] = (0.0, 0.0, 0.0)


def lens_sharpness(flat: np.ndarray, centres: np.ndarray, pitch_px: float) -> np.ndarray:
    """Mean |Laplacian| of the flattened image over a disc of 0.35 pitch around each centre
    (K,): the micro-image's own detail, away from its border."""
    lap = cv2.Laplacian(np.asarray(flat, np.float32), cv2.CV_32F, ksize=3)
    np.abs(lap, out=lap)
    radius = 0.35 * pitch_px
    half = int(np.ceil(radius))
    yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
    inside = np.hypot(xx, yy) <= radius
    dy, dx = yy[inside], xx[inside]
    rows, cols = lap.shape
    c = np.clip(np.rint(centres[:, 0]).astype(np.int64), 0, cols - 1)
    r = np.clip(np.rint(centres[:, 1]).astype(np.int64), 0, rows - 1)
    # the disc mean at the centres only: a filter over the whole frame costs more than the
    # lenses' own pixels
    return _disc_means(lap, r, c, dy.astype(np.int64), dx.astype(np.int64))


@numba.njit(parallel=True, cache=True)
def _disc_means(image, r, c, dy, dx):  # pragma: no cover - compiled
    """Mean of ``image`` at (r + dy, c + dx) per centre, indices beyond the frame mirrored
    back once (edge pixel repeated, as BORDER_REFLECT): offsets must be smaller than the
    frame (a disc of 0.35 pitch is, in any frame that holds lenses)."""
    rows, cols = image.shape
    out = np.empty(r.shape[0])
    reach_y, reach_x = np.abs(dy).max(), np.abs(dx).max()
    for k in numba.prange(r.shape[0]):
        acc = 0.0
        if reach_y <= r[k] < rows - reach_y and reach_x <= c[k] < cols - reach_x:
            for w in range(dy.shape[0]):   # inside the frame (nearly every lens): no mirror
                acc += image[r[k] + dy[w], c[k] + dx[w]]
        else:
            for w in range(dy.shape[0]):
                y, x = r[k] + dy[w], c[k] + dx[w]
                y = -y - 1 if y < 0 else (2 * rows - 1 - y if y >= rows else y)
                x = -x - 1 if x < 0 else (2 * cols - 1 - x if x >= cols else x)
                acc += image[y, x]
        out[k] = acc / dy.shape[0]
    return out


def local_contrast(indices: np.ndarray, sharpness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """log sharpness of each lens minus the mean over its six neighbours (which are of the two
    other types), for the lenses whose neighbours are all present: the scene's own detail
    varies over the frame far more than between neighbours, and cancels. Returns (which lenses,
    values)."""
    log_s = np.log(np.maximum(sharpness, 1e-12))
    if not len(indices):
        return np.empty(0, np.int64), np.empty(0)
    # lens number by index, with a frame of -1 around it for the missing neighbours
    at = indices - indices.min(axis=0) + 1
    lookup = np.full(tuple(at.max(axis=0) + 2), -1, np.int64)
    lookup[at[:, 0], at[:, 1]] = np.arange(len(indices))
    steps = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1))
    near = np.stack([lookup[at[:, 0] + di, at[:, 1] + dj] for di, dj in steps], axis=1)
    rows = np.flatnonzero((near >= 0).all(axis=1))
    return rows, log_s[rows] - log_s[near[rows]].mean(axis=1)


def classify(flat: np.ndarray, indices: np.ndarray, centres: np.ndarray,
             pitch_px: float) -> LensTypes | None:
    """The lens types of a hex array, or None when the three cosets do not differ (a
    single-focus array, or a frame without detail) or when the frame's depths do not tell
    which coset is focused where."""
    sharp = lens_sharpness(flat, centres, pitch_px)
    rows, local = local_contrast(indices, sharp)
    coset = (indices[:, 0] - indices[:, 1]) % 3
    groups = [local[coset[rows] == k] for k in range(3)]
    if min(len(g) for g in groups) < 10:
        return None
    p_value = anova_p_value(groups)
    if not p_value < SIGNIFICANCE:
        return None
    g = lens_virtual_depth(flat, indices, centres, pitch_px)
    order = types_by_depth(g[rows], local, coset[rows])
    if order is None:
        return None
    rank, change = order                      # coset of type 0, 1, 2
    type_of_coset = np.empty(3, np.int8)
    type_of_coset[rank] = np.arange(3)
    means = np.array([float(np.median(gr)) for gr in groups])
    return LensTypes(types=type_of_coset[coset],
                     sharpness=tuple(float(np.exp(v)) for v in means[rank]), p_value=p_value,
                     change=tuple(float(v) for v in change[rank]))


def lens_virtual_depth(flat: np.ndarray, indices: np.ndarray, centres: np.ndarray,
                       pitch_px: float) -> np.ndarray:
    """g of every lens (NaN where unknown), Keplerian (g > 1) or Galilean (g < -1): the sign
    whose matches are the more confident."""
    from plenocli.depth.lenslet import lens_depth
    from plenocli.model.lensgrid import LensGrid

    scale = min(1.0, DEPTH_PITCH_PX / float(pitch_px))
    xy = np.asarray(centres, float)
    frame = np.asarray(flat, np.float32)
    if scale < 0.9:
        frame = cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        xy = (xy + 0.5) * scale - 0.5
    grid = LensGrid(float(pitch_px) * scale, 0.0, tuple(float(v) for v in xy[0]), "hex",
                    centres_xy=xy, indices=np.asarray(indices))
    best, score = None, -1.0
    for bounds in ((2.0, 12.0), (-12.0, -2.0)):
        try:
            found = lens_depth(frame, grid, g_range=bounds)
        except ValueError:
            continue
        if float(np.median(found.confidence)) > score:
            best, score = found, float(np.median(found.confidence))
        if score >= CLEAR_MATCH:
            break   # a clear Keplerian match: the Galilean search would only cost time
    if best is None:
        return np.full(len(indices), np.nan)
    # lens_depth lists the lenses whose centres lie in the frame, in the grid's order
    inside = (np.isfinite(xy).all(axis=1) & (xy[:, 0] >= 0) & (xy[:, 0] <= frame.shape[1] - 1)
              & (xy[:, 1] >= 0) & (xy[:, 1] <= frame.shape[0] - 1))
    out = np.full(len(indices), np.nan)
    out[inside] = np.where(best.confidence >= 0.3, best.g, np.nan)
    return out


def types_by_depth(g: np.ndarray, local: np.ndarray, coset: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """(cosets ordered type 0, 1, 2; each coset's change of relative sharpness from the near
    third of the frame's |g| to its far third), or None when the depths spread too little,
    when the near- and the far-focused types' changes are within SLOPE_SEPARATION standard
    errors (the third coset is type 1 by elimination), or when those two types do not swap
    places between the near and the far third (a blur that does not depend on depth).
    Medians, not a line fit: relative sharpness peaks inside a type's range and has outliers
    on textureless lenses."""
    known = np.isfinite(g)
    if known.sum() < 30:
        return None
    depth = np.abs(g)
    q1, q3 = np.percentile(depth[known], (25, 75))
    if q3 - q1 < MIN_DEPTH_SPREAD:
        return None
    low, high = np.percentile(depth[known], (100 / 3, 200 / 3))
    change, error, at_near, at_far = np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3)
    for k in range(3):
        near = local[known & (coset == k) & (depth <= low)]
        far = local[known & (coset == k) & (depth >= high)]
        if min(len(near), len(far)) < 10:
            return None
        at_near[k], at_far[k] = float(np.median(near)), float(np.median(far))
        change[k] = at_far[k] - at_near[k]
        # standard error of a median: 1.2533 sigma / sqrt(n), sigma from the MAD
        spread = [1.4826 * float(np.median(np.abs(v - np.median(v)))) for v in (near, far)]
        error[k] = 1.2533 * float(np.hypot(spread[0] / np.sqrt(len(near)),
                                           spread[1] / np.sqrt(len(far))))
    rank = np.argsort(change)          # sharpness falling fastest with |g|: the near-focused
    first, last = rank[0], rank[-1]
    if not (at_near[first] > at_near[last] and at_far[first] < at_far[last]):
        return None   # no crossing: one type is sharper everywhere, which says nothing of depth
    # the near- and the far-focused types decide; the third coset is type 1 by elimination
    if change[last] - change[first] < SLOPE_SEPARATION * np.hypot(error[first], error[last]):
        return None
    return rank, change


def anova_p_value(groups: list[np.ndarray]) -> float:
    """p-value of the one-way ANOVA F test that the groups share one mean (as
    ``scipy.stats.f_oneway``, whose module alone would take 0.5 s of the command's start)."""
    values = np.concatenate(groups)
    grand = values.mean()
    between = sum(len(g) * (g.mean() - grand) ** 2 for g in groups)
    within = sum(((g - g.mean()) ** 2).sum() for g in groups)
    df_between, df_within = len(groups) - 1, len(values) - len(groups)
    if not within > 0:
        return 0.0 if between > 0 else 1.0
    return float(special.fdtrc(df_between, df_within,
                               (between / df_between) / (within / df_within)))
