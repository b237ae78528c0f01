"""Numba kernels of lenslet depth: micro-image profile, normalisation, matching between
neighbouring micro-images, and the footprint rendering onto the refocused grid.

Lens k is centred at (cx[k], cy[k]); ``nb`` (K, N) lists its neighbours (-1: none). A pixel p of
micro-image i at offset u = p - c_i shows the scene point that micro-image j shows at offset
u - (c_j - c_i) q, q = 1 / g (docs/depth.md): at sensor position p + (c_j - c_i) (1 - q).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _bilinear(img, x, y):
    """img at (x, y) (x = column), NaN outside or next to a NaN."""
    rows, cols = img.shape
    if not (0.0 <= x < cols - 1 and 0.0 <= y < rows - 1):
        return np.nan
    c0 = int(x)
    r0 = int(y)
    fx = x - c0
    fy = y - r0
    top = img[r0, c0] * (1 - fx) + img[r0, c0 + 1] * fx
    bot = img[r0 + 1, c0] * (1 - fx) + img[r0 + 1, c0 + 1] * fx
    return top * (1 - fy) + bot * fy


@njit(cache=True, inline="always")
def _bilinear_grad(img, x, y, ex, ey):
    """(img, d img / d t) at (x, y) along the direction (ex, ey), from one bilinear cell."""
    rows, cols = img.shape
    if not (0.0 <= x < cols - 1 and 0.0 <= y < rows - 1):
        return np.nan, np.nan
    c0 = int(x)
    r0 = int(y)
    fx = x - c0
    fy = y - r0
    a = img[r0, c0]
    b = img[r0, c0 + 1]
    c = img[r0 + 1, c0]
    d = img[r0 + 1, c0 + 1]
    value = (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy
    gx = (b - a) * (1 - fy) + (d - c) * fy
    gy = (c - a) * (1 - fx) + (d - b) * fx
    return value, gx * ex + gy * ey


@njit(cache=True, parallel=True)
def profile_sums(frame, cx, cy, radius, half, chunks):
    """Sums and counts of the frame binned by offset from the lens centre (0.5 px bins,
    (4 half + 1) square), over pixels within ``radius`` of their lens centre."""
    n = 4 * half + 1
    sums = np.zeros((chunks, n, n))
    counts = np.zeros((chunks, n, n))
    rows, cols = frame.shape
    per = (cx.shape[0] + chunks - 1) // chunks
    r2 = radius * radius
    for ch in prange(chunks):
        for k in range(ch * per, min((ch + 1) * per, cx.shape[0])):
            for r in range(max(0, int(cy[k] - radius)), min(rows, int(cy[k] + radius) + 2)):
                for c in range(max(0, int(cx[k] - radius)), min(cols, int(cx[k] + radius) + 2)):
                    ux = c - cx[k]
                    uy = r - cy[k]
                    v = frame[r, c]
                    if ux * ux + uy * uy > r2 or not math.isfinite(v):
                        continue
                    bx = int(round(2 * ux)) + 2 * half
                    by = int(round(2 * uy)) + 2 * half
                    sums[ch, by, bx] += v
                    counts[ch, by, bx] += 1.0
    return sums.sum(axis=0), counts.sum(axis=0)


@njit(cache=True, inline="always")
def _usable(profile, half, ux, uy):
    bx = int(round(2 * ux)) + 2 * half
    by = int(round(2 * uy)) + 2 * half
    return 0 <= bx < profile.shape[1] and 0 <= by < profile.shape[0] and \
        math.isfinite(profile[by, bx])


@njit(cache=True)
def _lens_samples(img, x, y, profile, half, stride):
    """Pixels (x, y, value) of the micro-image centred at (x, y) that the matching uses: finite,
    within its usable disc, every ``stride``-th pixel in a checkerboard."""
    reach = half + 1
    r0 = int(y) - reach
    c0 = int(x) - reach
    size = (2 * reach + 2) ** 2
    xs = np.empty(size)
    ys = np.empty(size)
    vs = np.empty(size)
    n = 0
    for r in range(max(0, r0), min(img.shape[0], r0 + 2 * reach + 2)):
        for c in range(max(0, c0), min(img.shape[1], c0 + 2 * reach + 2)):
            if stride > 1 and (r + c) % stride:
                continue
            v = img[r, c]
            if math.isfinite(v) and _usable(profile, half, c - x, r - y):
                xs[n] = c
                ys[n] = r
                vs[n] = v
                n += 1
    return xs[:n], ys[:n], vs[:n]


@njit(cache=True)
def _baselines(cx, cy, nb, k):
    """Baselines (x, y) from lens k to each of its neighbours in ``nb`` that exist."""
    bx = np.empty(nb.shape[1])
    by = np.empty(nb.shape[1])
    n = 0
    for m in range(nb.shape[1]):
        j = nb[k, m]
        if j >= 0:
            bx[n] = cx[j] - cx[k]
            by[n] = cy[j] - cy[k]
            n += 1
    return bx[:n], by[:n]


@njit(cache=True, parallel=True)
def normalise(frame, cx, cy, profile, gain, half, out):
    """out[p] = frame[p] / gain(u) (bilinear between bins) where the profile is finite (the
    usable disc), else NaN (out must be NaN-filled). Usable discs never overlap, so lenses
    write disjoint pixels."""
    rows, cols = frame.shape
    reach = half + 1
    for k in prange(cx.shape[0]):
        for r in range(max(0, int(cy[k]) - reach), min(rows, int(cy[k]) + reach + 2)):
            for c in range(max(0, int(cx[k]) - reach), min(cols, int(cx[k]) + reach + 2)):
                ux = c - cx[k]
                uy = r - cy[k]
                if _usable(profile, half, ux, uy):
                    m = _bilinear(gain, 2 * (ux + half), 2 * (uy + half))
                    if m > 0:
                        out[r, c] = frame[r, c] / m


@njit(cache=True, parallel=True)
def match_costs(img, cx, cy, nb, profile, half, qs, stride):
    """Sum of squared differences and sample counts (K, len(qs)) of every lens against its
    neighbours ``nb`` at each candidate q (every ``stride``-th pixel in a checkerboard)."""
    n_lens = cx.shape[0]
    nq = qs.shape[0]
    ssd = np.zeros((n_lens, nq))
    cnt = np.zeros((n_lens, nq))
    for k in prange(n_lens):
        xs, ys, vs = _lens_samples(img, cx[k], cy[k], profile, half, stride)
        bx, by = _baselines(cx, cy, nb, k)
        for p in range(vs.shape[0]):
            for m in range(bx.shape[0]):
                for iq in range(nq):
                    q = qs[iq]
                    if not _usable(profile, half, xs[p] - cx[k] - bx[m] * q,
                                   ys[p] - cy[k] - by[m] * q):
                        continue
                    w = _bilinear(img, xs[p] + bx[m] * (1 - q), ys[p] + by[m] * (1 - q))
                    if math.isfinite(w):
                        ssd[k, iq] += (vs[p] - w) ** 2
                        cnt[k, iq] += 1.0
    return ssd, cnt


@njit(cache=True, parallel=True)
def refine_q(img, cx, cy, nb, profile, half, q0, qmin, qmax, iterations, stride):
    """Gauss-Newton steps on q of each lens, all its neighbours together: the residual
    img(p + B (1 - q)) - img(p) is linearised in q (derivative -B . grad img)."""
    n_lens = cx.shape[0]
    q = q0.copy()
    for k in prange(n_lens):
        if not math.isfinite(q[k]):
            continue
        xs, ys, vs = _lens_samples(img, cx[k], cy[k], profile, half, stride)
        bx, by = _baselines(cx, cy, nb, k)
        for _ in range(iterations):
            num = 0.0
            den = 0.0
            for p in range(vs.shape[0]):
                for m in range(bx.shape[0]):
                    if not _usable(profile, half, xs[p] - cx[k] - bx[m] * q[k],
                                   ys[p] - cy[k] - by[m] * q[k]):
                        continue
                    # d residual / d q = -B . grad
                    w, dq = _bilinear_grad(img, xs[p] + bx[m] * (1 - q[k]),
                                           ys[p] + by[m] * (1 - q[k]), -bx[m], -by[m])
                    if not (math.isfinite(w) and math.isfinite(dq)):
                        continue
                    num += (w - vs[p]) * dq
                    den += dq * dq
            if den <= 0.0:
                break
            q[k] = min(max(q[k] - num / den, qmin), qmax)
    return q


@njit(cache=True)
def render_footprints(cx, cy, g, weight, radius, s, rows_out, cols_out):
    """Each lens's value ``g`` spread around s c (where its centre lands whatever g) over a
    disc of ``radius`` output pixels, weighted by a tent (1 at the centre, 0 at the rim) times
    ``weight``. Returns (sum of w g, sum of w, sum of w * weight) maps."""
    sg = np.zeros((rows_out, cols_out))
    sw = np.zeros((rows_out, cols_out))
    sc = np.zeros((rows_out, cols_out))
    for k in range(cx.shape[0]):
        if not (math.isfinite(g[k]) and weight[k] > 0):
            continue
        X = s * cx[k]
        Y = s * cy[k]
        rad = radius
        for R in range(max(0, int(Y - rad)), min(rows_out, int(Y + rad) + 2)):
            for C in range(max(0, int(X - rad)), min(cols_out, int(X + rad) + 2)):
                d = math.sqrt((C - X) ** 2 + (R - Y) ** 2) / rad
                if d >= 1.0:
                    continue
                w = (1.0 - d) * weight[k]
                sg[R, C] += w * g[k]
                sw[R, C] += w
                sc[R, C] += w * weight[k]
    return sg, sw, sc
