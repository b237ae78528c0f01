"""Numba kernels of the photometric refinement: view b resampled by cubic B-splines at the
template points moved by the current homography, and in the same pass the photometric
residual and its Huber weight."""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, inline="always")
def _bspline_weights(f):
    """The four cubic B-spline weights of taps -1, 0, 1, 2 at fraction f in [0, 1)."""
    g = 1.0 - f
    f2 = f * f
    return (g * g * g / 6.0, (3.0 * f2 * f - 6.0 * f2 + 4.0) / 6.0,
            (-3.0 * f2 * f + 3.0 * f2 + 3.0 * f + 1.0) / 6.0, f2 * f / 6.0)


@njit(cache=True, inline="always")
def _sample(coeffs, g, x, y, bad):
    """(inside, value): the cubic B-spline with coefficients ``coeffs`` at g (x, y, 1); inside
    means at least a pixel within the image and not on a ``bad`` pixel ((0, 0): none is)."""
    rows, cols = coeffs.shape
    w = g[2, 0] * x + g[2, 1] * y + g[2, 2]
    bx = (g[0, 0] * x + g[0, 1] * y + g[0, 2]) / w
    by = (g[1, 0] * x + g[1, 1] * y + g[1, 2]) / w
    if not (1.0 <= bx <= cols - 2 and 1.0 <= by <= rows - 2):
        return False, 0.0
    if bad.shape[0] > 0 and bad[int(math.floor(by + 0.5)), int(math.floor(bx + 0.5))]:
        return False, 0.0
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
    return True, total


@njit(cache=True, nogil=True)
def warp_bspline(coeffs, g, xn, yn, bad, out, inside):
    """``out[i]``, ``inside[i]``: b (B-spline coefficients ``coeffs``) at g (xn[i], yn[i], 1)
    (g: 3 x 3, normalised template coordinates -> b pixels); see :func:`_sample`. Serial: it
    resamples the photometric fit's sample points, too few to pay for threads."""
    for i in range(xn.shape[0]):
        inside[i], out[i] = _sample(coeffs, g, xn[i], yn[i], bad)


@njit(cache=True, nogil=True)
def huber_residual(coeffs, g, xn, yn, template, bad, coef, degree, cut, err, weight):
    """``err[i]``: the residual in b's units e = (p b(g x) + o - a) / p at point i, with p =
    the ratio polynomial (``coef[:-1]`` on the monomials xn^i yn^j, i + j <= ``degree``, in
    the order of ``photometric._polynomial_terms``) and o = ``coef[-1]``; ``weight[i]``: its
    Huber weight min(1, cut / |e|). Both 0 at points outside b. Serial: the pairs of a layout
    are refined in threads at once."""
    terms = (degree + 1) * (degree + 2) // 2
    for i in range(xn.shape[0]):
        ok, value = _sample(coeffs, g, xn[i], yn[i], bad)
        if not ok:
            err[i] = weight[i] = 0.0
            continue
        x, y = xn[i], yn[i]
        ratio = 0.0
        xp = 1.0
        t = 0
        for a in range(degree + 1):
            inner = 0.0
            yp = 1.0
            for _ in range(degree + 1 - a):
                inner += coef[t] * yp
                yp *= y
                t += 1
            ratio += xp * inner
            xp *= x
        if abs(ratio) < 1e-6:
            ratio = 1.0
        e = (ratio * value + coef[terms] - template[i]) / ratio
        err[i] = e
        weight[i] = 1.0 if abs(e) <= cut else cut / abs(e)
