"""Numba kernel of the photometric refinement: view b resampled by cubic B-splines at the
template points moved by the current homography (one pass: no coordinate arrays)."""

from __future__ import annotations

import math

from numba import njit, prange


@njit(cache=True, inline="always")
def _bspline_weights(f):
    """The four cubic B-spline weights of taps -1, 0, 1, 2 at fraction f in [0, 1)."""
    g = 1.0 - f
    f2 = f * f
    return (g * g * g / 6.0, (3.0 * f2 * f - 6.0 * f2 + 4.0) / 6.0,
            (-3.0 * f2 * f + 3.0 * f2 + 3.0 * f + 1.0) / 6.0, f2 * f / 6.0)


@njit(cache=True, parallel=True)
def warp_bspline(coeffs, g, xn, yn, bad, out, inside):  # noqa: PLR0913 (numba kernel)
    """``out[i]`` = the cubic B-spline with coefficients ``coeffs`` (rows, cols) at g (xn[i],
    yn[i], 1) (g: 3 x 3, normalised template coordinates -> b pixels); ``inside[i]`` says the
    point lies at least a pixel within b and not on a ``bad`` pixel (a (0, 0) array: none is)."""
    rows, cols = coeffs.shape
    check_bad = bad.shape[0] > 0
    for i in prange(xn.shape[0]):
        x, y = xn[i], yn[i]
        w = g[2, 0] * x + g[2, 1] * y + g[2, 2]
        bx = (g[0, 0] * x + g[0, 1] * y + g[0, 2]) / w
        by = (g[1, 0] * x + g[1, 1] * y + g[1, 2]) / w
        ok = 1.0 <= bx <= cols - 2 and 1.0 <= by <= rows - 2
        if ok and check_bad:
            ok = not bad[int(math.floor(by + 0.5)), int(math.floor(bx + 0.5))]
        inside[i] = ok
        if not ok:
            out[i] = 0.0
            continue
        ix, iy = int(math.floor(bx)), int(math.floor(by))
        wx = _bspline_weights(bx - ix)
        wy = _bspline_weights(by - iy)
        total = 0.0
        for r in range(4):
            row = min(iy - 1 + r, rows - 1)
            acc = 0.0
            for c in range(4):
                acc += wx[c] * coeffs[row, min(ix - 1 + c, cols - 1)]
            total += wy[r] * acc
        out[i] = total

