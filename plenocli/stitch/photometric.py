"""Direct photometric refinement of a homography (or a shift) over the whole overlap.

Inverse-compositional Gauss-Newton (Baker-Matthews) on ``a(x) = p(x) b(H^-1 x) + o``: b resampled
by cubic B-splines, a smooth photometric ratio ``p`` (relative gain and vignetting) and an offset
``o`` refitted at every step, Huber weights, coordinates normalised to the overlap.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from plenocli.stitch.views import MODELS, corners_xy, fill_nan


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
    """(N, terms) monomials xn^i yn^j with i + j <= degree (coordinates in [-1, 1])."""
    xp, yp = [np.ones_like(xn)], [np.ones_like(yn)]
    for _ in range(degree):
        xp.append(xp[-1] * xn)
        yp.append(yp[-1] * yn)
    out = np.empty((xn.size, (degree + 1) * (degree + 2) // 2))
    k = 0
    for i in range(degree + 1):
        for j in range(degree + 1 - i):
            np.multiply(xp[i], yp[j], out=out[:, k])
            k += 1
    return out


def _template(a: np.ndarray, valid_a: np.ndarray, valid_b: np.ndarray, h_ab: np.ndarray,
              max_points: int):
    """The overlap pixels of a used as the template: their values, the normalising map
    (normalised template coordinates -> a pixels), their normalised coordinates and the
    steepest-descent images of the inverse-compositional homography update at identity."""
    rows, cols = a.shape
    cover = cv2.warpPerspective(valid_b.astype(np.float32), h_ab, (cols, rows),
                                flags=cv2.INTER_LINEAR) > 0.999
    cover = ndimage.binary_erosion(cover & valid_a, iterations=3)
    ys, xs = np.nonzero(cover)
    if ys.size < 256:
        raise ValueError(f"the overlap holds only {ys.size} px; too small to refine")
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    if ys.size > max_points:  # a fixed random subset (a regular subgrid biased the shift)
        keep = np.random.default_rng(0).choice(ys.size, max_points, replace=False)
        keep.sort()
        ys, xs = ys[keep], xs[keep]
    grad_y, grad_x = np.gradient(a[y0 - 1:y1 + 1, x0 - 1:x1 + 1])
    # normalised template coordinates (centre of the overlap, half its longer side) keep the
    # Gauss-Newton system well conditioned
    cx, cy, scale = (x0 + x1 - 1) / 2, (y0 + y1 - 1) / 2, max(x1 - x0, y1 - y0) / 2
    from_norm = np.array([[scale, 0.0, cx], [0.0, scale, cy], [0.0, 0.0, 1.0]])
    xn, yn = (xs - cx) / scale, (ys - cy) / scale
    gx = grad_x[ys - y0 + 1, xs - x0 + 1] * scale
    gy = grad_y[ys - y0 + 1, xs - x0 + 1] * scale
    radial = gx * xn + gy * yn
    steepest = np.stack([gx * xn, gx * yn, gx, gy * xn, gy * yn, gy, -xn * radial,
                         -yn * radial], axis=1)
    return a[ys, xs], from_norm, xn, yn, steepest


def _photometric_residual(warped: np.ndarray, template: np.ndarray, inside: np.ndarray,
                          poly: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residual of the photometric model a ~ p(x, y) * b + offset (p the smooth ratio of the
    views' gains and vignetting over the overlap, a linear least-squares fit) and its Huber
    weights (occlusions, ghosts or clipped pixels do not pull the fit)."""
    scaled = poly * warped[:, None]  # the ratio's columns; the offset's column is all ones
    used = scaled if inside.all() else scaled[inside]
    target = template[inside]
    sums = used.sum(axis=0)
    normal = np.empty((poly.shape[1] + 1,) * 2)
    normal[:-1, :-1] = used.T @ used
    normal[-1, :-1] = normal[:-1, -1] = sums
    normal[-1, -1] = len(target)
    rhs = np.append(used.T @ target, target.sum())
    del used
    coef = np.linalg.lstsq(normal, rhs, rcond=None)[0]
    err = scaled @ coef[:-1]
    err += coef[-1] - template
    err[~inside] = 0.0
    sigma = 1.4826 * float(np.median(np.abs(err[inside]))) + 1e-12
    weight = np.minimum(1.0, 3.0 * sigma / np.maximum(np.abs(err), 1e-30))
    weight[~inside] = 0.0
    return err, weight


def _refine_level(a: np.ndarray, b: np.ndarray, valid_a: np.ndarray, valid_b: np.ndarray,
                  h_ab: np.ndarray, *, max_points: int, iterations: int, degree: int,
                  tol_px: float, motion: str) -> tuple[np.ndarray, dict]:
    """One pyramid level of :func:`refine_homography` (float64 images, NaN already filled)."""
    template, from_norm, xn, yn, steepest = _template(a, valid_a, valid_b, h_ab, max_points)
    scale = from_norm[0, 0]
    if motion == "translation":
        steepest = steepest[:, [2, 5]]
    poly = _polynomial_terms(xn, yn, degree)
    coeffs = ndimage.spline_filter(b, order=3)
    bad_b = ndimage.binary_dilation(~valid_b, iterations=2)
    g = np.linalg.inv(h_ab) @ from_norm  # normalised template coordinates -> b pixels
    pts = np.stack([xn, yn, np.ones_like(xn)])
    step_px = np.inf
    err = np.zeros_like(template)
    use = np.ones(template.shape, bool)
    done = 0
    while done < iterations:
        done += 1
        q = g @ pts
        bx, by = q[0] / q[2], q[1] / q[2]
        inside = (bx >= 1) & (bx <= b.shape[1] - 2) & (by >= 1) & (by <= b.shape[0] - 2)
        bxi = np.clip(np.rint(bx), 0, b.shape[1] - 1).astype(int)
        byi = np.clip(np.rint(by), 0, b.shape[0] - 1).astype(int)
        inside &= ~bad_b[byi, bxi]
        if inside.sum() < 256:
            raise ValueError("the refinement left the overlap")
        warped = ndimage.map_coordinates(coeffs, [by, bx], order=3, prefilter=False,
                                         mode="nearest")
        err, weight = _photometric_residual(warped, template, inside, poly)
        use = inside
        weighted = steepest * weight[:, None]
        dp = np.linalg.solve(weighted.T @ steepest, weighted.T @ err)
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
    info = {"photometric_iterations": done, "photometric_step_px": step_px,
            "photometric_rms": float(np.sqrt(np.mean(err[use] ** 2))),
            "photometric_points": int(use.sum())}
    return h_new / h_new[2, 2], info


def _pyramid_level(fa, fb, valid_a, valid_b, level: int):
    """Images and validity masks of pyramid ``level`` (each level halves the size)."""
    if not level:
        return fa, fb, valid_a, valid_b
    la, lb = fa, fb
    for _ in range(level):
        la, lb = cv2.pyrDown(la), cv2.pyrDown(lb)
    va = cv2.resize(valid_a.astype(np.uint8), la.shape[::-1],
                    interpolation=cv2.INTER_NEAREST).astype(bool)
    vb = cv2.resize(valid_b.astype(np.uint8), lb.shape[::-1],
                    interpolation=cv2.INTER_NEAREST).astype(bool)
    return la, lb, va, vb


def refine_homography(a: np.ndarray, b: np.ndarray, h_ab: np.ndarray, *,
                      max_points: int = 400_000, iterations: int = 30, degree: int = 4,
                      tol_px: float = 1e-3,
                      motion: str = "homography", pyramid: bool = True
                      ) -> tuple[np.ndarray, dict]:
    """Refine a homography by direct photometric least squares over the whole overlap.

    Inverse-compositional Gauss-Newton (Baker-Matthews) on ``a(x) = p(x) b(H^-1 x) + o``, with
    b resampled by cubic B-splines (exact for band-limited data, unlike bilinear warps whose
    interpolation error biases the fit), a smooth photometric ratio ``p`` (2-D polynomial of
    ``degree`` over the overlap: relative gain and vignetting) and offset ``o`` refitted at
    every step, Huber weights, and coordinates normalised to the overlap. Coarse pyramid levels
    (factor 2) are used first for views larger than 1024 px.

    Parameters
    ----------
    a, b : (rows, cols) views (NaN = no data); b's pixels map into a's by ``h_ab``.
    h_ab : (3, 3) initial homography (b pixels -> a pixels), within a few px.
    max_points : at most this many overlap pixels are used per level (a regular subgrid).
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
    valid_a, valid_b = np.isfinite(a), np.isfinite(b)
    fa = fill_nan(np.asarray(a, np.float64))
    fb = fill_nan(np.asarray(b, np.float64))
    h = np.asarray(h_ab, np.float64) / h_ab[2, 2]
    levels = int(max(0, np.ceil(np.log2(max(a.shape) / 1024)))) if pyramid else 0
    info: dict = {}
    for level in range(levels, -1, -1):
        la, lb, va, vb = _pyramid_level(fa, fb, valid_a, valid_b, level)
        down = np.diag([0.5**level, 0.5**level, 1.0])  # pyrDown: level pixel = full pixel / 2^l
        h_level, info = _refine_level(la, lb, va, vb, down @ h @ np.linalg.inv(down),
                                      max_points=max_points, iterations=iterations,
                                      degree=degree, tol_px=tol_px * 0.5**level,
                                      motion=motion)
        h = np.linalg.inv(down) @ h_level @ down
        h /= h[2, 2]
    rows, cols = b.shape
    corners = corners_xy(b.shape)
    moved = cv2.perspectiveTransform(corners, h) - cv2.perspectiveTransform(
        corners, np.asarray(h_ab, np.float64) / h_ab[2, 2])
    if not np.isfinite(moved).all() or np.abs(moved).max() > 0.05 * max(rows, cols):
        raise ValueError("the photometric refinement ran away from the feature estimate")
    return h, info


