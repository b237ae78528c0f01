"""Per-lens centres: each micro-image's point-symmetry centre (every micro-image, white or
scene, Keplerian or Galilean, is point-symmetric about its centre on average: its vignetting
and its border are), and the independent checks built on the same property."""

from __future__ import annotations

import cv2
import numba
import numpy as np

from plenocli.model.lensgrid import LensGrid

EDGE_MARGIN = 0.25   # border (pitches, beyond the disc) where lenses keep the lattice


@numba.njit(parallel=True, cache=True)
def _symmetry_centres(values, cx, cy, radius, n_iter):  # pragma: no cover - compiled
    """Gauss-Newton point-symmetry centres: minimise sum_k w(|x_k - c|) (I(x_k) - I(2c - x_k))^2
    over the pixels x_k of a disc of ``radius`` around c; I(2c - x_k) bilinear."""
    rows, cols = values.shape
    out_x = cx.copy()
    out_y = cy.copy()
    ok = np.ones(cx.shape[0], np.bool_)
    r2 = radius * radius
    for k in numba.prange(cx.shape[0]):
        x, y = cx[k], cy[k]
        for _ in range(n_iter):
            r_lo, r_hi = int(np.ceil(y - radius)), int(np.floor(y + radius))
            c_lo, c_hi = int(np.ceil(x - radius)), int(np.floor(x + radius))
            if (r_lo < 1 or c_lo < 1 or r_hi > rows - 2 or c_hi > cols - 2
                    or 2 * y - r_hi < 0 or 2 * x - c_hi < 0
                    or 2 * y - r_lo > rows - 2 or 2 * x - c_lo > cols - 2):
                ok[k] = False
                break
            a11 = 0.0
            a12 = 0.0
            a22 = 0.0
            b1 = 0.0
            b2 = 0.0
            # the mirror 2c - x_k of every pixel has the same fractional part: one set of
            # bilinear weights per iteration
            fx2, fy2 = np.floor(2 * x), np.floor(2 * y)
            fx, fy = 2 * x - fx2, 2 * y - fy2
            ix2, iy2 = int(fx2), int(fy2)
            for r in range(r_lo, r_hi + 1):
                dy = r - y
                j0 = iy2 - r
                for c in range(c_lo, c_hi + 1):
                    dx = c - x
                    d2 = dx * dx + dy * dy
                    if d2 >= r2:
                        continue
                    t = 1.0 - d2 / r2
                    w = t * t
                    i0 = ix2 - c
                    v00 = values[j0, i0]
                    v01 = values[j0, i0 + 1]
                    v10 = values[j0 + 1, i0]
                    v11 = values[j0 + 1, i0 + 1]
                    top = v00 + fx * (v01 - v00)
                    bot = v10 + fx * (v11 - v10)
                    e = values[r, c] - (top + fy * (bot - top))
                    jx = -2.0 * ((1 - fy) * (v01 - v00) + fy * (v11 - v10))
                    jy = -2.0 * (bot - top)
                    a11 += w * jx * jx
                    a12 += w * jx * jy
                    a22 += w * jy * jy
                    b1 += w * jx * e
                    b2 += w * jy * e
            det = a11 * a22 - a12 * a12
            if det <= 0.0:
                ok[k] = False
                break
            sx = -(a22 * b1 - a12 * b2) / det
            sy = -(a11 * b2 - a12 * b1) / det
            step = np.hypot(sx, sy)
            if step > 0.1 * radius:   # far from the fixed point: damp
                sx *= 0.1 * radius / step
                sy *= 0.1 * radius / step
            x += sx
            y += sy
            if step < 1e-3:
                break
        out_x[k] = x
        out_y[k] = y
    return out_x, out_y, ok


def refine_centres(flat: np.ndarray, grid: LensGrid, *, window: float = 0.6,
                   n_iter: int = 5, near: tuple[np.ndarray, float] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-lens centres as point-symmetry centres of the micro-images.

    Each centre c minimises sum_k w(|x_k - c|) (I(x_k) - I(2c - x_k))^2 over the pixels x_k
    within ``window`` pitches of c (Gauss-Newton from the lattice position; w a smooth taper,
    I(2c - x_k) bilinear). A plain centroid weighs the flat top of a micro-image and ignores its
    edges, which carry the position; the symmetry fit uses the edges, and neighbours that
    overlap the window only add noise, not a systematic pull, as long as they are symmetric on
    average.

    Parameters
    ----------
    flat : (rows, cols) float32 flattened image (see :func:`flatten`, blur of >= 1 pitch: a
        narrower blur follows each lens's neighbours and tilts its micro-image)
    grid : the lattice to start from
    window : radius of the symmetry disc in units of the pitch
    near : (point (x, y), radius px): only the lenses whose lattice position is that close are
        refined (the others keep it, refined False)

    Returns
    -------
    indices (K, 2) int, centres (K, 2) float (x, y) px, refined (K,) bool
        Every lattice lens whose ideal centre is inside the image; lenses whose disc (or its
        mirror) leaves the image keep their ideal centre (refined False).
    """
    rows, cols = flat.shape
    grid = LensGrid(grid.pitch_px, grid.angle_rad, grid.offset_xy, grid.lattice,
                    image_shape=(rows, cols))
    idx, ideal = grid.lens_centres()
    radius = window * grid.pitch_px
    margin = radius + EDGE_MARGIN * grid.pitch_px + 2  # flattening is less sure at the border
    inner = ((ideal[:, 0] >= margin) & (ideal[:, 0] <= cols - 1 - margin)
             & (ideal[:, 1] >= margin) & (ideal[:, 1] <= rows - 1 - margin))
    if near is not None:
        inner &= np.hypot(*(ideal - np.asarray(near[0])).T) <= near[1]
    cx, cy, ok = _symmetry_centres(np.ascontiguousarray(flat, np.float32),
                                   ideal[inner, 0].copy(), ideal[inner, 1].copy(),
                                   float(radius), n_iter)
    refined = np.zeros(len(ideal), bool)
    refined[np.flatnonzero(inner)[ok]] = True
    centres = ideal.copy()
    centres[inner, 0] = np.where(ok, cx, ideal[inner, 0])
    centres[inner, 1] = np.where(ok, cy, ideal[inner, 1])
    return idx, centres, refined




def mean_micro_image(image: np.ndarray, centres: np.ndarray, *, half: int) -> np.ndarray:
    """Average of the micro-images around ``centres`` (K, 2), resampled bilinearly on a
    (2 half + 1)^2 grid centred on each centre: its symmetry centre is the grid's bias."""
    rows, cols = image.shape
    offs = np.arange(-half, half + 1, dtype=np.float32)
    acc = np.zeros((len(offs), len(offs)), np.float64)
    img = np.asarray(image, np.float32)
    keep = ((centres[:, 0] > half + 1) & (centres[:, 0] < cols - half - 2)
            & (centres[:, 1] > half + 1) & (centres[:, 1] < rows - half - 2))
    for x, y in centres[keep]:
        mapx = (x + offs)[None, :].repeat(len(offs), 0).astype(np.float32)
        mapy = (y + offs)[:, None].repeat(len(offs), 1).astype(np.float32)
        acc += cv2.remap(img, mapx, mapy, cv2.INTER_LINEAR)
    return acc / max(int(keep.sum()), 1)


def symmetry_centre(patch: np.ndarray, *, radius: float) -> tuple[float, float]:
    """Point-symmetry centre (dx, dy) of a patch relative to its middle pixel (px).

    Minimises sum over |r| < radius of (P(c + r) - P(c - r))^2 over sub-pixel c (bilinear
    resampling, Nelder-Mead)."""
    from scipy.optimize import minimize

    n = patch.shape[0]
    mid = (n - 1) / 2
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32) - np.float32(mid)
    inside = np.hypot(xx, yy) < radius
    p = patch.astype(np.float32)

    def cost(c):
        fwd = cv2.remap(p, (mid + c[0] + xx).astype(np.float32),
                        (mid + c[1] + yy).astype(np.float32), cv2.INTER_CUBIC)
        back = cv2.remap(p, (mid + c[0] - xx).astype(np.float32),
                         (mid + c[1] - yy).astype(np.float32), cv2.INTER_CUBIC)
        return float(np.sum((fwd - back)[inside] ** 2))

    res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-12, "maxiter": 400})
    return float(res.x[0]), float(res.x[1])

