"""The sub-pixel shift between two neighbouring views: a masked NCC search over the expected
overlap (:mod:`plenocli.stitch.ncc`), then ECC and a photometric least-squares polish."""

from __future__ import annotations

import cv2
import numpy as np

from plenocli.stitch.errors import StitchError
from plenocli.stitch.ncc import search_highpassed
from plenocli.stitch.photometric import match_photometry, refine_homography
from plenocli.stitch.quality import aligned_correlation
from plenocli.stitch.views import (
    at_own_level,
    highpass,
    translation_matrix,
    valid_eroded,
)

# the ambiguity test's runner-up lies further than this from the match (a periodic scene's next
# period; nearer peaks are the match's own shoulders)
RUNNER_UP_EXCLUSION_PX = 6


def shifted_overlap(a: np.ndarray, b: np.ndarray, dy: int, dx: int):
    """Same-size crops of a and b over their overlap for b(q) <-> a(q + (dy, dx)), or None."""
    rows, cols = a.shape
    y0, y1 = max(0, dy), min(rows, rows + dy)
    x0, x1 = max(0, dx), min(cols, cols + dx)
    if y1 - y0 < 8 or x1 - x0 < 8:
        return None
    return a[y0:y1, x0:x1], b[y0 - dy:y1 - dy, x0 - dx:x1 - dx], (y0, x0)


def estimate_translation(a: np.ndarray, b: np.ndarray, *, direction: str = "h",
                         max_overlap: float = 0.7, min_overlap_px: int = 16,
                         max_cross_px: int | None = None,
                         min_correlation: float = 0.4,
                         prior: tuple[float, float] | None = None,
                         tolerance_px: float | None = None,
                         max_ambiguity: float = 0.9) -> tuple[float, float, dict]:
    """Sub-pixel shift of view b against view a: b's pixel (y, x) shows a's (y + dy, x + dx).

    Parameters
    ----------
    a, b : (rows, cols) views (NaN allowed); b lies to the right of a (``direction="h"``) or
        below it (``"v"``).
    max_overlap : largest overlap searched, fraction of the view width (height for "v").
    min_overlap_px : width of b's edge strip used for the search (the overlap must be at least
        this wide).
    max_cross_px : largest shift across the stitching direction searched (default 10 % of the
        view's other side).
    min_correlation : below this normalised cross-correlation over the overlap the views are
        declared not to overlap (``StitchError``).
    prior : expected shift (dy, dx) px, e.g. from a rig model or an expected overlap; the
        search is then restricted to ``tolerance_px`` (default 5 % of the view, >= 8 px)
        around it instead of the whole range above.
    max_ambiguity : the best whole-overlap correlation elsewhere (outside 6 px of the match)
        must stay below this fraction of the match's, else the match is ambiguous (a periodic
        scene, or too little overlap) and ``StitchError`` is raised instead of a ghosted result.

    Returns
    -------
    dy, dx : shift in px. info : dict with ``correlation``, ``overlap_px``, ``overlap_fraction``,
    ``runner_up_correlation``.
    """
    if direction not in ("h", "v"):
        raise ValueError(f"direction must be 'h' or 'v', got {direction!r}")
    if not 0 < max_overlap <= 1:
        raise ValueError(f"max_overlap must be in (0, 1], got {max_overlap}")
    if direction == "v":
        dx, dy, info = estimate_translation(
            a.T, b.T, direction="h", max_overlap=max_overlap, min_overlap_px=min_overlap_px,
            max_cross_px=max_cross_px, min_correlation=min_correlation,
            prior=None if prior is None else (prior[1], prior[0]), tolerance_px=tolerance_px,
            max_ambiguity=max_ambiguity)
        return dy, dx, info
    a, b, ha, hb = _textures(a, b)
    dy_range, dx_range, min_pixels = _search_ranges(
        a.shape, b.shape, max_overlap=max_overlap, min_overlap_px=min_overlap_px,
        max_cross_px=max_cross_px, prior=prior, tolerance_px=tolerance_px)
    dy0, dx0, best, second = search_highpassed(ha, hb, valid_eroded(a), valid_eroded(b),
                                               dy_range=dy_range, dx_range=dx_range,
                                               min_pixels=min_pixels,
                                               exclusion_px=RUNNER_UP_EXCLUSION_PX)
    if best <= -1.0:  # the search's mark for a shift with nothing to correlate
        raise StitchError(f"nothing to correlate: no shift searched leaves {min_pixels} pixels "
                          "known (not NaN) in both views and textured; the views may not "
                          "overlap, or their overlap is unknown (NaN) or flat")
    if best < min_correlation:
        raise StitchError(f"no reliable overlap found between the views (best normalised "
                         f"correlation {best:.2f} < {min_correlation}); the views may not "
                         "overlap, or the overlap has no texture")
    if second >= max_ambiguity * best:
        # with an expected shift already given, asking for one again does not help
        advice = ("the scene repeats within the tolerance around the expected shift: with "
                  "--overlap, narrow --overlap-tolerance; with --rig, give a transform solved "
                  "on another capture of the rig (--transform-in)") if prior is not None \
            else "give the expected overlap (--overlap) or the rig (--rig)"
        raise StitchError(f"ambiguous overlap: shifts correlating {best:.2f} and {second:.2f} "
                          f"(a periodic scene?); {advice}")
    ty, tx, method = _ecc_subpixel(a, b, dy0, dx0)
    dy, dx, method = _photometric_polish(a, b, dy0 - ty, dx0 - tx, method)
    correlation = aligned_correlation(ha, hb, translation_matrix(dy, dx), a, b)
    overlap_px = a.shape[1] - dx
    info = {"correlation": correlation, "overlap_px": float(overlap_px),
            "overlap_fraction": float(overlap_px / a.shape[1]), "refinement": method,
            "runner_up_correlation": second}
    if not np.isfinite(correlation) or correlation < min_correlation:
        raise StitchError(f"no reliable overlap found between the views (best normalised "
                         f"correlation {correlation:.2f} < {min_correlation}); the views may not "
                         "overlap, or the overlap has no texture")
    return float(dy), float(dx), info


def _textures(a: np.ndarray, b: np.ndarray):
    """The views at their own levels and their high-passed textures; a view without texture
    (against its own level) is refused. At its own level, the search, ECC and the photometric
    polish see two views of one scale whatever their unit or exposure."""
    a, b = at_own_level(a, b)
    ha, hb = highpass(a), highpass(b)
    for name, h, view in (("a", ha, a), ("b", hb, b)):
        if float(h.std()) <= 1e-6 * max(float(np.nanmax(np.abs(view))), 1e-30):
            raise StitchError(f"view {name} has no texture (flat image); stitching needs "
                             "structure in the overlap")
    return a, b, ha, hb


def _search_ranges(shape_a: tuple[int, int], shape_b: tuple[int, int], *, max_overlap: float,
                   min_overlap_px: int, max_cross_px: int | None,
                   prior: tuple[float, float] | None, tolerance_px: float | None):
    """The inclusive integer shift ranges (dy, dx) to search for b right of a, and the
    fewest overlap pixels a shift must have."""
    rows, cols = shape_a
    cross = int(max_cross_px if max_cross_px is not None else round(0.1 * rows))
    cross = min(cross, rows // 4)
    strip = max(int(min_overlap_px), 8)
    x_start = max(0, int(np.floor(cols * (1 - max_overlap))))
    if cols - x_start < strip:
        raise ValueError(f"max_overlap {max_overlap} leaves less than {strip} px to search")
    if prior is not None:
        tol = int(np.ceil(tolerance_px if tolerance_px is not None
                          else max(8.0, 0.05 * max(rows, cols))))
        dy_range = (int(np.floor(prior[0])) - tol, int(np.ceil(prior[0])) + tol)
        dx_range = (int(np.floor(prior[1])) - tol, int(np.ceil(prior[1])) + tol)
    else:
        dy_range, dx_range = (-cross, cross), (x_start, cols - strip)
    min_pixels = max(64, strip * (rows - 2 * cross) // 2)
    rows_b, cols_b = shape_b
    dy_range = (max(dy_range[0], 1 - rows_b), min(dy_range[1], rows - 1))
    dx_range = (max(dx_range[0], 1 - cols_b), min(dx_range[1], cols - 1))
    if dy_range[1] < dy_range[0] or dx_range[1] < dx_range[0]:
        raise StitchError("the expected overlap lies outside the views; check --layout and "
                         "--overlap")
    return dy_range, dx_range, min_pixels


def _ecc_subpixel(a: np.ndarray, b: np.ndarray, dy0: int, dx0: int) -> tuple[float, float, str]:
    """Sub-pixel correction (ty, tx) of the integer match (dy0, dx0) by ECC (translation) on the
    overlap of the raw views, and the method that gave it. ECC is invariant to gain and
    offset, and the raw views resample without the bias a high-pass would add."""
    crops = shifted_overlap(a, b, dy0, dx0)
    if crops is None:
        raise StitchError("no overlap found between the views; check the layout (--layout) and "
                         "that the views overlap")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return 0.0, 0.0, "template"
    _, _, (y0, x0) = crops
    ra, rb = np.asarray(a, np.float32), np.asarray(b, np.float32)
    rows_ov, cols_ov = crops[0].shape
    ca = ra[y0:y0 + rows_ov, x0:x0 + cols_ov]
    cb = rb[y0 - dy0:y0 - dy0 + rows_ov, x0 - dx0:x0 - dx0 + cols_ov]
    warp = np.float32([[1, 0, x0 - dx0], [0, 1, y0 - dy0]])  # crop of a -> b
    method = "ecc"
    # two passes: the photometric ratio field is re-estimated once the shift is sub-pixel
    # (views with no-data regions, e.g. undistorted canvases, skip ECC above: it cannot mask
    # them). ECC stops once its correlation gains less than 1e-6: the photometric fit sets the
    # final shift (1e-8 took ten times the iterations for the same final result)
    for _ in range(2):
        b_on_a = cv2.warpAffine(rb, warp, (cols_ov, rows_ov),
                                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_REPLICATE)
        template = match_photometry(ca, b_on_a, np.ones(ca.shape, bool))
        try:
            _, warp = cv2.findTransformECC(template, rb, warp, cv2.MOTION_TRANSLATION,
                                           (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200,
                                            1e-6), None, 1)
        except cv2.error:
            method = "phase-correlation"
            break
    if method == "ecc":
        ty, tx = float(warp[1, 2]) - (y0 - dy0), float(warp[0, 2]) - (x0 - dx0)
    else:
        window = cv2.createHanningWindow((ca.shape[1], ca.shape[0]), cv2.CV_64F)
        (tx, ty), _ = cv2.phaseCorrelate(cb.astype(np.float64), ca.astype(np.float64), window)
    if abs(ty) > 2 or abs(tx) > 2:  # refinement ran away: keep the integer match
        return 0.0, 0.0, "template"
    return ty, tx, method


# pixels of the overlap the polish fits a shift on: two parameters are fixed within ~0.002 px by
# 1e5 textured pixels (4e5, the homography's budget, moved the demo's shifts by < 0.002 px and
# took four times as long); fitted at full resolution only: its start (ECC or the template's
# sub-pixel peak) is within a pixel, where coarse levels add time, not accuracy
POLISH_POINTS = 100_000


def _photometric_polish(a: np.ndarray, b: np.ndarray, dy: float, dx: float,
                        method: str) -> tuple[float, float, str]:
    """Final photometric least squares with spline resampling (ECC's bilinear warps leave a
    texture-dependent bias of up to ~0.2 px on smooth, large views); the shift is kept when
    the polish runs away (more than 1 px) or fails."""
    try:
        (sa, sb), (off_y, off_x) = _translation_crops(a.shape, b.shape, dy, dx)
        shifted, _ = refine_homography(a[sa], b[sb], translation_matrix(dy - off_y, dx - off_x),
                                       motion="translation", max_points=POLISH_POINTS,
                                       pyramid=False)
    except ValueError:
        return dy, dx, method
    ry, rx = float(shifted[1, 2]) + off_y, float(shifted[0, 2]) + off_x
    if abs(ry - dy) < 1 and abs(rx - dx) < 1:
        return ry, rx, method + "+photometric"
    return dy, dx, method


def _translation_crops(shape_a: tuple[int, int], shape_b: tuple[int, int], dy: float,
                       dx: float, margin_px: int = 16):
    """Crops of a and b (slices) holding their overlap for b(q) <-> a(q + (dy, dx)) plus a
    margin, and the offset to subtract from the shift in the crops' coordinates (crop origins
    on multiples of 4, so the refinement's pyramid samples as on the whole views)."""
    slices_a, slices_b, offset = [], [], []
    for n_a, n_b, t in zip(shape_a, shape_b, (dy, dx), strict=True):
        lo = max(0, (int(np.floor(max(t, 0.0))) - margin_px) // 4 * 4)
        hi = min(n_a, int(np.ceil(n_b + t)) + margin_px)
        lo_b = max(0, (int(np.floor(lo - t)) - margin_px) // 4 * 4)
        hi_b = min(n_b, int(np.ceil(hi - t)) + margin_px)
        slices_a.append(slice(lo, hi))
        slices_b.append(slice(lo_b, hi_b))
        offset.append(lo - lo_b)
    return (tuple(slices_a), tuple(slices_b)), tuple(offset)


