"""A homography between two neighbouring views: SIFT features, ratio test, matches restricted to
the expected direction (and prior), RANSAC, least squares, then the photometric refinement of
:mod:`plenocli.stitch.photometric`."""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from plenocli.stitch.errors import StitchError
from plenocli.stitch.photometric import refine_homography
from plenocli.stitch.quality import aligned_correlation
from plenocli.stitch.views import (
    HIGHPASS_SIGMA_PX,
    at_own_level,
    corners_xy,
    fill_nan,
    highpass,
    translation_matrix,
)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    lo, hi = np.percentile(image, [0.5, 99.5])
    return np.clip(255 * (image - lo) / max(hi - lo, 1e-12), 0, 255).astype(np.uint8)


def _reduced(image: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray | None]:
    """The view reduced ``factor`` times (area average, NaN filled), 8-bit, and where features
    may lie: not on the edges of no-data regions (None: everywhere)."""
    valid = np.isfinite(image)
    img = np.asarray(fill_nan(image), np.float32)
    mask = None if valid.all() else ndimage.binary_erosion(valid, iterations=4).astype(np.uint8)
    if factor > 1:
        size = (image.shape[1] // factor, image.shape[0] // factor)
        img = cv2.resize(img[:size[1] * factor, :size[0] * factor], size,
                         interpolation=cv2.INTER_AREA)
        mask = None if mask is None else cv2.resize(
            mask[:size[1] * factor, :size[0] * factor], size, interpolation=cv2.INTER_NEAREST)
    return _to_uint8(img), mask


def features(image: np.ndarray) -> tuple:
    """Keypoints (N, 2) float32 (x, y, view pixels) and descriptors of a view, its no-data
    edges left out; views over FEATURE_SIDE_PX are searched reduced by a power of 2 (the
    photometric refinement, full size, sets the result; the start need only be within its
    reach)."""
    factor = 1
    while max(image.shape) > FEATURE_SIDE_PX * factor:
        factor *= 2
    img, mask = _reduced(image, factor)
    sift = cv2.SIFT_create(nfeatures=MAX_FEATURES, contrastThreshold=0.01)
    keys, desc = sift.detectAndCompute(img, mask)
    pts = np.float32([k.pt for k in keys]).reshape(-1, 2)
    return (pts + 0.5) * factor - 0.5, desc


# the RANSAC start only needs to be within the photometric refinement's reach (its coarse
# level converges from a pixel or two); the refinement over the whole overlap sets the result.
# On the bench's 2 x 2 of 1500 px views, 1000 features on views reduced 4x start the refinement
# 0.2-1.1 px from the truth and end where 3000 on views reduced 2x do (0.1-0.4 px; SIFT there
# took 4 x the time, the matching 9 x)
MAX_FEATURES = 1000
FEATURE_SIDE_PX = 600
# the full-size photometric fit stops after an update under this (px at the overlap's corners):
# each step leaves a quarter to a twentieth of the previous (1e-2 saved a third of the full-size
# steps but moved the bench's far corners by up to 0.009 px)
REFINE_TOL_PX = 5e-3


def _feature_matches(a: np.ndarray, b: np.ndarray, *, direction: str, min_inliers: int,
                     prior: tuple[float, float] | None, tolerance_px: float | None,
                     found: tuple | None = None):
    """Matched SIFT points (pa, pb), (N, 2) float32 (x, y), that pass the ratio test and lie
    in the expected direction (and within ``tolerance_px`` of the prior shift). ``found``: the
    views' :func:`features`, when already detected."""
    (ka, da), (kb, db) = found if found is not None else (features(a), features(b))
    if da is None or db is None or len(ka) < min_inliers or len(kb) < min_inliers:
        raise StitchError(f"too few features ({len(ka)} and {len(kb)}) to fit a homography; the "
                         "views have no texture; try --model translation")
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(db, da, k=2)
    good = [m for m, *rest in knn if rest and m.distance < 0.75 * rest[0].distance]
    pb = kb[[m.queryIdx for m in good]].reshape(-1, 2)
    pa = ka[[m.trainIdx for m in good]].reshape(-1, 2)
    axis = 0 if direction == "h" else 1
    ahead = pa[:, axis] - pb[:, axis] > 0  # b lies after a: its points sit later in a
    if prior is not None:
        tol = tolerance_px if tolerance_px is not None else max(8.0, 0.05 * max(a.shape))
        shift = pa - pb
        ahead &= (np.abs(shift[:, 0] - prior[1]) <= tol) & (np.abs(shift[:, 1] - prior[0]) <= tol)
    pa, pb = pa[ahead], pb[ahead]
    if len(pa) < min_inliers:
        raise StitchError(f"only {len(pa)} feature matches in the expected overlap direction; the "
                         "views may not overlap or have no texture")
    return pa, pb


def _ransac(pa: np.ndarray, pb: np.ndarray, *, ransac_px: float, min_inliers: int):
    """RANSAC homography b -> a, then least squares (Levenberg-Marquardt) on its inliers: a
    better start than the minimal-sample model RANSAC returns. Returns it and the inliers."""
    h, inl = cv2.findHomography(pb, pa, cv2.RANSAC, ransac_px, maxIters=5000, confidence=0.999)
    if h is None or inl is None or int(inl.sum()) < min_inliers:
        n_in = 0 if inl is None else int(inl.sum())
        raise StitchError(f"only {n_in} RANSAC inliers (need {min_inliers}); the views may not "
                         "overlap or have no texture")
    inl = inl.ravel().astype(bool)
    h_ls, _ = cv2.findHomography(pb[inl], pa[inl], 0)
    h = h_ls if h_ls is not None else h
    return h / h[2, 2], inl


def estimate_homography(a: np.ndarray, b: np.ndarray, *, direction: str = "h",
                        min_inliers: int = 12, ransac_px: float = 2.0,
                        min_correlation: float = 0.4,
                        prior: tuple[float, float] | None = None,
                        tolerance_px: float | None = None,
                        max_overlap: float | None = 0.7,
                        found: tuple | None = None) -> tuple[np.ndarray, dict]:
    """Homography mapping view b's pixels to view a's, from SIFT + RANSAC + photometric
    refinement. With ``prior`` = expected shift (dy, dx), only matches displaced by it within
    ``tolerance_px`` (default 5 % of the view, >= 8 px) are kept: a periodic scene's false
    matches, a period away, are left out. A fit that lays view b over more than ``max_overlap``
    of view a (or not after it at all) is refused: on a periodic scene that is a false match.

    Returns
    -------
    h_ab : (3, 3) float64 with ``h_ab[2, 2] == 1``.
    info : dict with ``matches``, ``inliers``, ``reprojection_rms_px`` (RANSAC inliers under the
        final homography), ``correlation``, ``refinement``.
    """
    if direction not in ("h", "v"):
        raise ValueError(f"direction must be 'h' or 'v', got {direction!r}")
    pa, pb = _feature_matches(a, b, direction=direction, min_inliers=min_inliers, prior=prior,
                              tolerance_px=tolerance_px, found=found)
    h, inl = _ransac(pa, pb, ransac_px=ransac_px, min_inliers=min_inliers)
    refined, method, correlation, photometric = _refined(a, b, h)
    proj = cv2.perspectiveTransform(pb[inl].reshape(-1, 1, 2).astype(np.float64), refined)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - pa[inl]) ** 2, axis=1))))
    if not np.isfinite(correlation) or correlation < min_correlation:
        raise StitchError(f"no reliable overlap found between the views (normalised correlation "
                         f"{correlation:.2f} < {min_correlation} after the homography fit)")
    overlap = None if max_overlap is None else check_overlap(refined, a.shape, direction,
                                                             max_overlap)
    info = {"matches": int(len(pa)), "inliers": int(inl.sum()), "reprojection_rms_px": rms,
            "correlation": correlation, "refinement": method, "overlap_fraction": overlap,
            **photometric}
    return refined, info


def _refined(a: np.ndarray, b: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, str, float, dict]:
    """The photometric refinement of ``h`` unless it lowers the overlap correlation by more than
    0.01 (then ``h``): the homography, its method, its correlation and the refinement's figures.
    """
    a, b = at_own_level(a, b)
    overlap_correlation = OverlapCorrelation(a, b)
    try:
        candidate, photometric = refine_homography(a, b, h, tol_px=REFINE_TOL_PX)
    except ValueError:
        return h, "ransac", overlap_correlation(h), {}
    after = overlap_correlation(candidate)
    if after >= 0.99:  # a correlation is at most 1: the start's cannot be 0.01 above
        return candidate, "photometric", after, photometric
    before = overlap_correlation(h)
    if np.isfinite(after) and not after < before - 0.01:
        return candidate, "photometric", after, photometric
    return h, "ransac", before, photometric


def _box(points: np.ndarray, shape: tuple[int, int], margin: int) -> tuple[slice, slice] | None:
    """(row, column) slices of a (rows, cols) image around ``points`` (x, y) plus ``margin``."""
    if not np.isfinite(points).all():
        return None
    x0, y0 = np.maximum(np.floor(points.min(axis=0)).astype(int) - margin, 0)
    x1, y1 = np.ceil(points.max(axis=0)).astype(int) + margin + 1
    x1, y1 = min(x1, shape[1]), min(shape[0], y1)
    return (slice(y0, y1), slice(x0, x1)) if x1 > x0 and y1 > y0 else None


def _inside(inner: tuple[slice, slice], outer: tuple[slice, slice]) -> bool:
    return all(o.start <= i.start and i.stop <= o.stop for i, o in zip(inner, outer, strict=True))


class OverlapCorrelation:
    """:func:`plenocli.stitch.quality.aligned_correlation` of the high-passed views a and b
    under a homography, computed on crops that hold b's footprint on a plus the high-pass's
    reach (4 sigma) and the warp's kernel: the value of the whole views without high-passing
    and warping them. The crops are high-passed once, with room for the refinement's moves,
    and made again only for a homography that leaves them."""

    REACH_PX = int(4 * HIGHPASS_SIGMA_PX) + 4
    ROOM_PX = 16

    def __init__(self, a: np.ndarray, b: np.ndarray):
        self.a, self.b, self.crops = a, b, None

    def _boxes(self, h_ab: np.ndarray, margin: int):
        box_a = _box(cv2.perspectiveTransform(corners_xy(self.b.shape), h_ab).reshape(-1, 2),
                     self.a.shape, margin)
        if box_a is None:
            return None
        ys, xs = box_a
        corners = np.float64([[xs.start, ys.start], [xs.stop - 1, ys.start],
                              [xs.stop - 1, ys.stop - 1], [xs.start, ys.stop - 1]])
        box_b = _box(cv2.perspectiveTransform(corners.reshape(-1, 1, 2), np.linalg.inv(h_ab))
                     .reshape(-1, 2), self.b.shape, margin)
        return None if box_b is None else (box_a, box_b)

    def __call__(self, h_ab: np.ndarray) -> float:
        need = self._boxes(h_ab, self.REACH_PX)
        if need is None:
            return float("nan")
        if self.crops is None or not all(_inside(n, c) for n, c in zip(need, self.crops[0],
                                                                         strict=True)):
            boxes = self._boxes(h_ab, self.REACH_PX + self.ROOM_PX)
            ca, cb = self.a[boxes[0]], self.b[boxes[1]]
            self.crops = boxes, ca, cb, highpass(ca), highpass(cb)
        (box_a, box_b), ca, cb, ha, hb = self.crops
        h_crop = (translation_matrix(-box_a[0].start, -box_a[1].start) @ h_ab
                  @ translation_matrix(box_b[0].start, box_b[1].start))
        return aligned_correlation(ha, hb, h_crop, ca, cb)


def overlap_fraction(h_ab: np.ndarray, shape: tuple[int, int], direction: str) -> float:
    """The fraction of view a that view b covers along the stitching direction under ``h_ab``
    (views of ``shape``; negative: b lies past a's far edge, or before it)."""
    axis = 0 if direction == "h" else 1
    size = shape[1 - axis]  # along the overlap direction: width for "h", height for "v"
    centre = np.array([[[(shape[1] - 1) / 2, (shape[0] - 1) / 2]]])
    step = float(cv2.perspectiveTransform(centre, h_ab)[0, 0, axis] - centre[0, 0, axis])
    return 1.0 - step / size


def check_overlap(h_ab: np.ndarray, shape: tuple[int, int], direction: str,
                  max_overlap: float) -> float:
    """The fraction of view a that view b covers along the stitching direction under ``h_ab``
    (views of ``shape``); refused when not in (0, ``max_overlap``]: a false match, as a
    periodic scene gives."""
    overlap = overlap_fraction(h_ab, shape, direction)
    if not 0 < overlap <= max_overlap:
        raise StitchError(f"the homography lays one view {100 * overlap:.0f} % over the other "
                         f"(at most {100 * max_overlap:.0f} % expected): a false match, as a "
                         "periodic scene gives; use --overlap or --rig")
    return overlap
