"""Direct photometric refinement of a homography (or a shift) over the whole overlap.

Inverse-compositional Gauss-Newton (Baker-Matthews) on ``a(x) = p(x) b(H^-1 x) + o``: b resampled
by cubic B-splines, a smooth photometric ratio ``p`` (relative gain and vignetting) and an offset
``o`` refitted at every step, Huber weights, coordinates normalised to the overlap.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from plenocli.stitch.bspline import huber_residual, warp_bspline
from plenocli.stitch.quality import bounding_box
from plenocli.stitch.views import MODELS, corners_xy, fill_nan, translation_matrix


def match_photometry(template: np.ndarray, other: np.ndarray, mask: np.ndarray,
                     sigma_px: float = 8.0) -> np.ndarray:
    """``template`` times the smooth ratio field blur(other) / blur(template) over ``mask``.

    ``other`` is the second view already resampled onto ``template`` (roughly aligned). Both
    blurs see the same scene content, so their ratio is the relative vignetting and gain
    between the views; removing it keeps ECC from being pulled by fall-offs that differ
    between the views (each view is darker towards its own edge).
    """
    m = mask.astype(np.float32)
    t = np.where(mask, template, 0).astype(np.float32)
    o = np.where(mask, other, 0).astype(np.float32)
    blur_m = cv2.GaussianBlur(m, (0, 0), sigma_px)
    blur_t = cv2.GaussianBlur(t, (0, 0), sigma_px) / np.maximum(blur_m, 1e-6)
    blur_o = cv2.GaussianBlur(o, (0, 0), sigma_px) / np.maximum(blur_m, 1e-6)
    scale = float(np.abs(blur_t[mask]).max()) if mask.any() else 0.0
    if scale == 0 or float(blur_t[mask].min()) <= 0.05 * scale:
        return template.astype(np.float32)  # signed or dark data: leave as is
    ratio = np.where(mask, blur_o / np.maximum(blur_t, 1e-6 * scale), 1.0)
    return (template * ratio).astype(np.float32)


def _polynomial_terms(xn: np.ndarray, yn: np.ndarray, degree: int) -> np.ndarray:
    """(terms, N) monomials xn^i yn^j with i + j <= degree (coordinates in [-1, 1])."""
    xp, yp = [np.ones_like(xn)], [np.ones_like(yn)]
    for _ in range(degree):
        xp.append(xp[-1] * xn)
        yp.append(yp[-1] * yn)
    return np.stack([xp[i] * yp[j] for i in range(degree + 1) for j in range(degree + 1 - i)])


_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def _erode(mask: np.ndarray, iterations: int) -> np.ndarray:
    """Binary erosion by the 4-neighbour cross, outside the image counting as False."""
    return cv2.erode(mask.astype(np.uint8), _CROSS, iterations=iterations,
                     borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)


def _template(a: np.ndarray, valid_a: np.ndarray | None, valid_b: np.ndarray | None,
              b_shape: tuple[int, int], h_ab: np.ndarray, max_points: int):
    """The overlap pixels of a used as the template: their values, the normalising map
    (normalised template coordinates -> a pixels), their normalised coordinates and the
    steepest-descent images (8, N) of the inverse-compositional homography update at
    identity. Of a larger overlap the ``max_points`` pixels of strongest gradient are kept
    (see :func:`_strongest`)."""
    rows, cols = a.shape
    src = np.ones(b_shape, np.uint8) if valid_b is None else valid_b.astype(np.uint8)
    cover = cv2.warpPerspective(src * np.uint8(255), h_ab, (cols, rows),
                                flags=cv2.INTER_LINEAR) == 255
    if valid_a is not None:
        cover &= valid_a
    cover = _erode(cover, 3)
    count, box = int(np.count_nonzero(cover)), bounding_box(cover)
    if count < 256:
        raise ValueError(f"the overlap holds only {count} px; too small to refine")
    (y0, y1), (x0, x1) = (box[0].start, box[0].stop), (box[1].start, box[1].stop)
    ys, xs = np.nonzero(cover if count <= max_points else _strongest(a, cover, max_points))
    # normalised template coordinates (centre of the overlap, half its longer side) keep the
    # Gauss-Newton system well conditioned
    cx, cy, scale = (x0 + x1 - 1) / 2, (y0 + y1 - 1) / 2, max(x1 - x0, y1 - y0) / 2
    from_norm = np.array([[scale, 0.0, cx], [0.0, scale, cy], [0.0, 0.0, 1.0]])
    xn, yn = ((xs - cx) / scale).astype(np.float32), ((ys - cy) / scale).astype(np.float32)
    half = np.float32(scale / 2)  # central differences (the points lie 3 px inside the crop)
    gx = (a[ys, xs + 1] - a[ys, xs - 1]) * half
    gy = (a[ys + 1, xs] - a[ys - 1, xs]) * half
    radial = gx * xn + gy * yn
    steepest = np.stack([gx * xn, gx * yn, gx, gy * xn, gy * yn, gy, -xn * radial,
                         -yn * radial])
    return a[ys, xs], from_norm, xn, yn, steepest


def _strongest(a: np.ndarray, cover: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` pixels of ``cover`` where a's gradient is strongest (ties at the threshold
    all kept). A pixel's information on the geometry grows with its squared gradient (the
    Gauss-Newton Hessian is the sum of the steepest-descent images' outer products): flat pixels
    add noise and time, little else. In a textured overlap the strongest quarter of the pixels
    holds about 60 % of the information, more than a random half."""
    energy = np.zeros_like(a)
    gx, gy = a[1:-1, 2:] - a[1:-1, :-2], a[2:, 1:-1] - a[:-2, 1:-1]
    energy[1:-1, 1:-1] = gx * gx + gy * gy
    inside = energy[cover]
    threshold = np.partition(inside, inside.size - count)[inside.size - count]
    return cover & (energy >= threshold)


def _photometric_fit(warped: np.ndarray, template: np.ndarray, poly: np.ndarray
                     ) -> tuple[np.ndarray, float]:
    """The photometric model a ~ p(x, y) * b + offset (p the smooth ratio of the views' gains
    and vignetting over the overlap) fitted by linear least squares on sample points (``poly``:
    their monomials, (terms, n)): the coefficients (the offset last) and the robust scale
    (1.4826 MAD) of the residual in b's units (see :func:`_refine_level`)."""
    used = poly * warped  # the offset's row is all ones
    normal = np.empty((poly.shape[0] + 1,) * 2)
    normal[:-1, :-1] = used @ used.T
    normal[-1, :-1] = normal[:-1, -1] = used.sum(axis=1, dtype=np.float64)
    normal[-1, -1] = len(template)
    rhs = np.append(np.einsum("ij,j->i", used, template), template.sum(dtype=np.float64))
    coef = np.linalg.lstsq(normal, rhs, rcond=None)[0]
    ratio = np.einsum("i,ij->j", coef[:-1].astype(np.float32), poly)
    ratio[np.abs(ratio) < 1e-6] = 1.0
    err = (ratio * warped + coef[-1] - template) / ratio
    return coef, 1.4826 * float(np.median(np.abs(err))) + 1e-12


# the photometric ratio's 15 coefficients and the residual's scale are fixed by this many
# points (more only cost time: 20 000 and 50 000 end within 5e-4 px); the geometry uses every
# point
PHOTOMETRIC_POINTS = 20_000
# the crops' margin around the overlap: the refinement's moves and the reach of the cubic
# B-spline prefilter (its edge effect falls as 0.27^d over d px: 1e-9 at 16 px)
CROP_MARGIN_PX = 16
# coarse levels stop once an update moves the overlap's corners by less than this (full-size
# px): the full-size level starts within its one-step reach; iterating the coarse level further
# only refits its own noise
COARSE_TOL_PX = 0.02


def _refine_level(a: np.ndarray, b: np.ndarray, valid_a: np.ndarray | None,
                  valid_b: np.ndarray | None, h_ab: np.ndarray, *, max_points: int,
                  iterations: int, degree: int, tol_px: float, motion: str
                  ) -> tuple[np.ndarray, dict]:
    """One pyramid level of :func:`refine_homography` (float32 images, NaN already filled;
    validity masks None where everything is valid). Each step fits the photometric ratio and
    the residual's scale on every k-th point (PHOTOMETRIC_POINTS), then resamples b at all
    points, with their residuals and Huber weights, in one pass
    (:mod:`plenocli.stitch.bspline`), and solves the normal equations of the geometry.
    The residual is taken in b's units: the steepest-descent images are a's gradients, which
    b shows divided by the ratio (in a's units a gain of 0.85 shortened every step by 15 %,
    a linear convergence at that rate)."""
    template, from_norm, xn, yn, steepest = _template(a, valid_a, valid_b, b.shape, h_ab,
                                                      max_points)
    scale = from_norm[0, 0]
    if motion == "translation":
        steepest = steepest[[2, 5]]
    every = max(1, len(xn) // PHOTOMETRIC_POINTS)
    sample_x, sample_y = xn[::every].copy(), yn[::every].copy()
    sample_t = template[::every].copy()
    poly = _polynomial_terms(sample_x, sample_y, degree)
    coeffs = ndimage.spline_filter(b, order=3, output=np.float32)
    bad_b = np.zeros((0, 0), bool) if valid_b is None else ~_erode(valid_b, 2)
    g = np.linalg.inv(h_ab) @ from_norm  # normalised template coordinates -> b pixels
    warped, inside = np.empty_like(sample_t), np.empty(sample_t.shape, bool)
    err, weight = np.empty_like(template), np.empty_like(template)
    full_hess = (steepest @ steepest.T).astype(np.float64)
    step_px, done = np.inf, 0
    while done < iterations:
        done += 1
        warp_bspline(coeffs, g, sample_x, sample_y, bad_b, warped, inside)
        if np.count_nonzero(inside) < 16 * len(poly):
            raise ValueError("the refinement left the overlap")
        coef, sigma = _photometric_fit(warped[inside], sample_t[inside], poly[:, inside])
        # Huber weights (cut at 3 sigma): occlusions, ghosts or clipped pixels do not pull
        huber_residual(coeffs, g, xn, yn, template, bad_b, coef, degree, 3.0 * sigma, err,
                       weight)
        # the Hessian of all points at weight 1 less that of the few down-weighted or outside
        low = np.flatnonzero(weight < 1)
        less = steepest[:, low]
        hess = full_hess - ((less * (1 - weight[low])) @ less.T).astype(np.float64)
        # products of a matrix and a vector by einsum: OpenBLAS's threads cost more than
        # these sums on a loaded machine
        grad = np.einsum("ij,j->i", steepest, weight * err).astype(np.float64)
        dp = np.linalg.solve(hess, grad)
        if motion == "translation":
            dp = np.array([0.0, 0.0, dp[0], 0.0, 0.0, dp[1], 0.0, 0.0])
        update = np.array([[1 + dp[0], dp[1], dp[2]], [dp[3], 1 + dp[4], dp[5]],
                           [dp[6], dp[7], 1.0]])
        g = g @ np.linalg.inv(update)
        g /= g[2, 2]
        step_px = float(np.abs(dp).max() * scale)
        if step_px < tol_px:
            break
    h_new = from_norm @ np.linalg.inv(g)
    count = int(np.count_nonzero(weight))
    info = {"photometric_iterations": done, "photometric_step_px": step_px,
            "photometric_rms": float(np.sqrt(np.dot(err, err) / max(count, 1))),
            "photometric_points": count}
    return h_new / h_new[2, 2], info


def _pyramid_level(fa, fb, valid_a, valid_b, level: int):
    """Images and validity masks of pyramid ``level`` (each level halves the size)."""
    if not level:
        return fa, fb, valid_a, valid_b
    la, lb = fa, fb
    for _ in range(level):
        la, lb = cv2.pyrDown(la), cv2.pyrDown(lb)
    va, vb = (None if v is None else cv2.resize(v.astype(np.uint8), img.shape[::-1],
                                               interpolation=cv2.INTER_NEAREST).astype(bool)
              for v, img in ((valid_a, la), (valid_b, lb)))
    return la, lb, va, vb


def _box(points: np.ndarray, shape: tuple[int, int], margin: int, align: int):
    """(row slice, column slice) of a (rows, cols) image holding ``points`` (x, y) plus
    ``margin`` px, starting on multiples of ``align`` (pyramid levels sample as on the whole
    image)."""
    if not np.isfinite(points).all():
        raise ValueError("the homography sends the overlap to infinity")
    lo = np.floor(points.min(axis=0)).astype(int) - margin
    hi = np.ceil(points.max(axis=0)).astype(int) + margin + 1
    x0, y0 = (max(0, v) // align * align for v in lo)
    x1, y1 = min(shape[1], hi[0]), min(shape[0], hi[1])
    if x1 - x0 < 8 or y1 - y0 < 8:
        raise ValueError("the views do not overlap under the homography; too small to refine")
    return slice(y0, y1), slice(x0, x1)


def _overlap_crops(a: np.ndarray, b: np.ndarray, h_ab: np.ndarray, align: int):
    """Crops of a and b that hold their overlap under ``h_ab`` (plus CROP_MARGIN_PX) and the
    crop origins (x, y)."""
    on_a = cv2.perspectiveTransform(corners_xy(b.shape), h_ab).reshape(-1, 2)
    box_a = _box(on_a, a.shape, CROP_MARGIN_PX, align)
    corners_a = np.float64([[box_a[1].start, box_a[0].start], [box_a[1].stop, box_a[0].start],
                            [box_a[1].stop, box_a[0].stop], [box_a[1].start, box_a[0].stop]])
    on_b = cv2.perspectiveTransform(corners_a.reshape(-1, 1, 2), np.linalg.inv(h_ab))
    box_b = _box(on_b.reshape(-1, 2), b.shape, CROP_MARGIN_PX, align)
    return a[box_a], b[box_b], (box_a[1].start, box_a[0].start), (box_b[1].start, box_b[0].start)


def _prepared(image: np.ndarray):
    """float32 image, NaN filled, and its validity (None: valid everywhere)."""
    valid = np.isfinite(image)
    image = np.asarray(image, np.float32)
    if valid.all():
        return image, None
    return fill_nan(image), valid


def refine_homography(a: np.ndarray, b: np.ndarray, h_ab: np.ndarray, *,
                      max_points: int = 200_000, iterations: int = 30, degree: int = 4,
                      tol_px: float = 1e-3,
                      motion: str = "homography", pyramid: bool = True
                      ) -> tuple[np.ndarray, dict]:
    """Refine a homography by direct photometric least squares over the whole overlap.

    Inverse-compositional Gauss-Newton (Baker-Matthews) on ``a(x) = p(x) b(H^-1 x) + o``, with
    b resampled by cubic B-splines (exact for band-limited data, unlike bilinear warps whose
    interpolation error biases the fit), a smooth photometric ratio ``p`` (2-D polynomial of
    ``degree`` over the overlap: relative gain and vignetting) and offset ``o`` refitted at
    every step, Huber weights, and coordinates normalised to the overlap. Only the crops of a
    and b that hold the overlap are used. Coarse pyramid levels (factor 2) are used first for
    views larger than 1024 px; they stop at COARSE_TOL_PX, the full-size level at ``tol_px``.

    Parameters
    ----------
    a, b : (rows, cols) views (NaN = no data); b's pixels map into a's by ``h_ab``.
    h_ab : (3, 3) initial homography (b pixels -> a pixels), within a few px.
    max_points : at most this many overlap pixels are used at full size, those of strongest
        gradient; a coarse level a quarter of its finer one's.
    iterations : Gauss-Newton steps per level.
    degree : degree of the photometric ratio polynomial.
    tol_px : stop when the update moves the overlap's corners by less than this (px).
    motion : "homography" (8 parameters) or "translation" (only the shift is updated).
    pyramid : start on the coarse levels; False fits at full resolution only (a shift already
        within a pixel converges there as well: the coarse levels add time, not accuracy).

    Returns
    -------
    h_ab : (3, 3) refined homography, ``h_ab[2, 2] == 1``.
    info : ``photometric_iterations``, ``photometric_step_px`` (last update), ``photometric_rms``
        (residual, image units), ``photometric_points``.

    Raises
    ------
    ValueError
        When the overlap is too small or the refinement runs away (more than 5 % of the view
        size from ``h_ab``); the caller keeps its initial estimate.
    """
    if motion not in MODELS:
        raise ValueError(f"motion must be one of {MODELS}, got {motion!r}")
    h0 = np.asarray(h_ab, np.float64) / h_ab[2, 2]
    levels = int(max(0, np.ceil(np.log2(max(a.shape) / 1024)))) if pyramid else 0
    crop_a, crop_b, (xa, ya), (xb, yb) = _overlap_crops(a, b, h0, 2**levels)
    fa, valid_a = _prepared(crop_a)
    fb, valid_b = _prepared(crop_b)
    to_crop, from_crop = translation_matrix(-ya, -xa), translation_matrix(yb, xb)
    h = to_crop @ h0 @ from_crop
    info: dict = {}
    for level in range(levels, -1, -1):
        la, lb, va, vb = _pyramid_level(fa, fb, valid_a, valid_b, level)
        down = np.diag([0.5**level, 0.5**level, 1.0])  # pyrDown: level pixel = full pixel / 2^l
        level_tol = max(tol_px, COARSE_TOL_PX) if level else tol_px
        h_level, info = _refine_level(la, lb, va, vb, down @ h @ np.linalg.inv(down),
                                      max_points=max_points // 4**level, iterations=iterations,
                                      degree=degree, tol_px=level_tol * 0.5**level,
                                      motion=motion)
        h = np.linalg.inv(down) @ h_level @ down
        h /= h[2, 2]
    h = np.linalg.inv(to_crop) @ h @ np.linalg.inv(from_crop)
    h /= h[2, 2]
    rows, cols = b.shape
    corners = corners_xy(b.shape)
    moved = cv2.perspectiveTransform(corners, h) - cv2.perspectiveTransform(corners, h0)
    if not np.isfinite(moved).all() or np.abs(moved).max() > 0.05 * max(rows, cols):
        raise ValueError("the photometric refinement ran away from the feature estimate")
    return h, info
