"""Lens types of a multi-focus array: three micro-lens focal lengths interleaved on the hex
lattice, each type on one coset of the index-3 sub-lattice ((i - j) mod 3). At a given depth
the types image the scene with different sharpness, so the cosets differ in the high-frequency
energy of their micro-images while lenses of one coset agree."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np
from scipy import special

SIGNIFICANCE = 1e-6   # a one-way ANOVA p-value below this: the cosets differ in sharpness


@dataclass(frozen=True)
class LensTypes:
    """Type (0 = sharpest in this frame) of every lens, the median sharpness of each type
    relative to its neighbours, and the ANOVA p-value of the difference."""

    types: np.ndarray          # (K,) int8
    sharpness: tuple[float, float, float]
    p_value: float


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
    for k in numba.prange(r.shape[0]):
        acc = 0.0
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
    single-focus array, or a frame without detail)."""
    sharp = lens_sharpness(flat, centres, pitch_px)
    rows, local = local_contrast(indices, sharp)
    coset = (indices[:, 0] - indices[:, 1]) % 3
    groups = [local[coset[rows] == k] for k in range(3)]
    if min(len(g) for g in groups) < 10:
        return None
    p_value = anova_p_value(groups)
    if not p_value < SIGNIFICANCE:
        return None
    means = np.array([float(np.median(g)) for g in groups])
    rank = np.argsort(-means)                 # coset of type 0, 1, 2
    type_of_coset = np.empty(3, np.int8)
    type_of_coset[rank] = np.arange(3)
    return LensTypes(types=type_of_coset[coset],
                     sharpness=tuple(float(np.exp(v)) for v in means[rank]), p_value=p_value)


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
