"""Cancel sub-aperture cross-talk: solve the per-pixel mixing of the views.

Behind a prism rig every pixel of view k records ``O_k = sum_j M_kj T_j``, with ``T_j`` the image
seen through pupil part j and ``M`` a small (V x V) matrix that varies slowly over the frame and
per colour. ``M`` is measured from masked-pupil whites (``plenocli.crosstalk.measure_mixing``) on
a grid of nodes (tile centres) and is bilinear between them (linear beyond the outer nodes).
With ``M_jj = 1`` (the normalisation the measurement gives), ``T_j`` is what view j would record
without cross-talk.

Per pixel the solve matrix is ``A = M^-1``, or with Tikhonov regularisation ``lambda``
``A = (M^T M + lambda^2 I)^-1 M^T``: each singular component of M is damped by
``s^2 / (s^2 + lambda^2)``, so well-conditioned pixels (every ``s >> lambda``) barely change and
ill-conditioned ones stop amplifying noise. The noise gain of view k, ``||row_k(A)||_2``, is the
standard deviation of its output for unit, independent noise in every input view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from plenocli.model.mixing import MAX_REGULARISE, MixingField
from plenocli.model.mixing import axis_weights as _axis_weights

SINGULAR_PIVOT = 1e-9  # a pivot below this (M entries are ~1) means M is singular there


@dataclass(frozen=True)
class UnmixResult:
    """``views`` (V, rows, cols) float32 clean views; ``noise_gain`` (V, rows, cols) float32 or
    None; ``singular_pixels``: pixels where M could not be inverted (their output is NaN)."""

    views: np.ndarray
    noise_gain: np.ndarray | None
    singular_pixels: int


@numba.njit(cache=True, inline="always")
def _solve_matrix(m, lam2, a, work, normal, normal_inv):
    """A = M^-1 (lam2 = 0) or (M^T M + lam2 I)^-1 M^T into ``a``; False if singular."""
    v = m.shape[0]
    if lam2 == 0.0:
        return _invert(m, a, work)
    for i in range(v):
        for j in range(v):
            s = 0.0
            for k in range(v):
                s += m[k, i] * m[k, j]
            normal[i, j] = s + (lam2 if i == j else 0.0)
    if not _invert(normal, normal_inv, work):
        return False
    for i in range(v):
        for j in range(v):
            s = 0.0
            for k in range(v):
                s += normal_inv[i, k] * m[j, k]
            a[i, j] = s
    return True


@numba.njit(cache=True, inline="always")
def _invert(m, a, work):
    """A = M^-1: closed forms for 2 x 2 and 4 x 4, Gauss-Jordan otherwise; False if singular."""
    v = m.shape[0]
    if v == 2:
        det = m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]
        if abs(det) < SINGULAR_PIVOT:
            return False
        a[0, 0], a[0, 1] = m[1, 1] / det, -m[0, 1] / det
        a[1, 0], a[1, 1] = -m[1, 0] / det, m[0, 0] / det
        return True
    if v == 4:
        return _inverse4(m, a)
    return _gauss_jordan(m, a, work)


@numba.njit(cache=True, inline="always")
def _gauss_jordan(m, a, work):
    """A = M^-1 by Gauss-Jordan with partial pivoting on [M | I]; False if singular."""
    v = m.shape[0]
    for i in range(v):
        for j in range(v):
            work[i, j] = m[i, j]
            a[i, j] = 1.0 if i == j else 0.0
    for col in range(v):
        piv = col
        for r in range(col + 1, v):
            if abs(work[r, col]) > abs(work[piv, col]):
                piv = r
        if abs(work[piv, col]) < SINGULAR_PIVOT:
            return False
        if piv != col:
            for j in range(v):
                work[col, j], work[piv, j] = work[piv, j], work[col, j]
                a[col, j], a[piv, j] = a[piv, j], a[col, j]
        inv = 1.0 / work[col, col]
        for j in range(v):
            work[col, j] *= inv
            a[col, j] *= inv
        for r in range(v):
            if r != col:
                f = work[r, col]
                if f != 0.0:
                    for j in range(v):
                        work[r, j] -= f * work[col, j]
                        a[r, j] -= f * a[col, j]
    return True


@numba.njit(cache=True, inline="always")
def _inverse4(m, a):
    """A = M^-1 of a 4 x 4 M by cofactors (no pivoting branches); False if singular. Laplace
    expansion over the row pairs (0, 1) and (2, 3): the minors of one pair and the entries of
    one row of the other make each column of the adjugate. M is read whole before A is
    written (so the compiler need not reload it after each store)."""
    r0, r1 = (m[0, 0], m[0, 1], m[0, 2], m[0, 3]), (m[1, 0], m[1, 1], m[1, 2], m[1, 3])
    r2, r3 = (m[2, 0], m[2, 1], m[2, 2], m[2, 3]), (m[3, 0], m[3, 1], m[3, 2], m[3, 3])
    s, c = _minors(r0, r1), _minors(r2, r3)
    det = s[0] * c[5] - s[1] * c[4] + s[2] * c[3] + s[3] * c[2] - s[4] * c[1] + s[5] * c[0]
    if abs(det) < SINGULAR_PIVOT:
        return False
    d = 1.0 / det
    _adjugate_column(a, 0, r1, c, d)
    _adjugate_column(a, 1, r0, c, -d)
    _adjugate_column(a, 2, r3, s, d)
    _adjugate_column(a, 3, r2, s, -d)
    return True


@numba.njit(cache=True, inline="always")
def _minors(p, q):
    """The six 2 x 2 minors of rows p and q, over the column pairs 01 02 03 12 13 23."""
    return (p[0] * q[1] - q[0] * p[1], p[0] * q[2] - q[0] * p[2], p[0] * q[3] - q[0] * p[3],
            p[1] * q[2] - q[1] * p[2], p[1] * q[3] - q[1] * p[3], p[2] * q[3] - q[2] * p[3])


@numba.njit(cache=True, inline="always")
def _adjugate_column(a, col, r, t, scale):
    """Column ``col`` of A: the cofactors from row ``r`` of M and the minors ``t`` of the
    other row pair, times ``scale`` (+-1/det)."""
    a[0, col] = (r[1] * t[5] - r[2] * t[4] + r[3] * t[3]) * scale
    a[1, col] = (-r[0] * t[5] + r[2] * t[2] - r[3] * t[1]) * scale
    a[2, col] = (r[0] * t[4] - r[1] * t[2] + r[3] * t[0]) * scale
    a[3, col] = (-r[0] * t[3] + r[1] * t[1] - r[2] * t[0]) * scale


@numba.njit(cache=True, parallel=True)
def _unmix_kernel(obs, nodes, pattern, r0, r1, wr, c0, c1, wc, lam2, out, gain, want_gain,
                  singular):
    """Per pixel: bilinear M of the pixel's colour, solve matrix A, T = A O (numba kernel: one
    image row per parallel task; the nodes are first blended along the row's position)."""
    n_col, v = nodes.shape[0], nodes.shape[1]
    rows, cols = obs.shape[1], obs.shape[2]
    n_nc = nodes.shape[4]
    for y in numba.prange(rows):
        row_m = np.empty((n_col, v, v, n_nc))
        wy = wr[y]
        for c in range(n_col):
            for k in range(v):
                for j in range(v):
                    for b in range(n_nc):
                        row_m[c, k, j, b] = ((1.0 - wy) * nodes[c, k, j, r0[y], b]
                                             + wy * nodes[c, k, j, r1[y], b])
        m = np.empty((v, v))
        a = np.empty((v, v))
        work = np.empty((v, v))
        normal = np.empty((v, v))
        normal_inv = np.empty((v, v))
        bad = 0
        for x in range(cols):
            c = pattern[y & 1, x & 1]
            wx = wc[x]
            lo, hi = c0[x], c1[x]
            for k in range(v):
                for j in range(v):
                    m[k, j] = (1.0 - wx) * row_m[c, k, j, lo] + wx * row_m[c, k, j, hi]
            ok = _solve_matrix(m, lam2, a, work, normal, normal_inv)
            if not ok:
                bad += 1
            for k in range(v):
                s = 0.0
                for j in range(v):
                    s += a[k, j] * obs[j, y, x]
                out[k, y, x] = s if ok else np.nan
                if want_gain:
                    g = 0.0
                    for j in range(v):
                        g += a[k, j] * a[k, j]
                    gain[k, y, x] = np.sqrt(g) if ok else np.inf
        singular[y] = bad


@numba.njit(cache=True, parallel=True)
def _unmix2_kernel(obs, nodes, pattern, r0, r1, wr, c0, c1, wc, lam2, out, gain, want_gain,
                   singular):
    """Two views: the closed-form solve matrix, M^-1 or (M^T M + lam2 I)^-1 M^T (numba kernel,
    one image row per parallel task)."""
    n_col = nodes.shape[0]
    rows, cols = obs.shape[1], obs.shape[2]
    n_nc = nodes.shape[4]
    for y in numba.prange(rows):
        row_m = np.empty((n_col, 2, 2, n_nc))
        wy = wr[y]
        for c in range(n_col):
            for k in range(2):
                for j in range(2):
                    for b in range(n_nc):
                        row_m[c, k, j, b] = ((1.0 - wy) * nodes[c, k, j, r0[y], b]
                                             + wy * nodes[c, k, j, r1[y], b])
        bad = 0
        for x in range(cols):
            c = pattern[y & 1, x & 1]
            wx = wc[x]
            lo, hi = c0[x], c1[x]
            m00 = (1.0 - wx) * row_m[c, 0, 0, lo] + wx * row_m[c, 0, 0, hi]
            m01 = (1.0 - wx) * row_m[c, 0, 1, lo] + wx * row_m[c, 0, 1, hi]
            m10 = (1.0 - wx) * row_m[c, 1, 0, lo] + wx * row_m[c, 1, 0, hi]
            m11 = (1.0 - wx) * row_m[c, 1, 1, lo] + wx * row_m[c, 1, 1, hi]
            if lam2 > 0.0:  # N = M^T M + lam2 I; A = N^-1 M^T
                n00 = m00 * m00 + m10 * m10 + lam2
                n01 = m00 * m01 + m10 * m11
                n11 = m01 * m01 + m11 * m11 + lam2
                det = n00 * n11 - n01 * n01
                a00, a01 = n11 * m00 - n01 * m01, n11 * m10 - n01 * m11
                a10, a11 = n00 * m01 - n01 * m00, n00 * m11 - n01 * m10
            else:
                det = m00 * m11 - m01 * m10
                a00, a01, a10, a11 = m11, -m01, -m10, m00
            if abs(det) < SINGULAR_PIVOT:
                bad += 1
                out[0, y, x] = np.nan
                out[1, y, x] = np.nan
                if want_gain:
                    gain[0, y, x] = np.inf
                    gain[1, y, x] = np.inf
                continue
            inv = 1.0 / det
            o0, o1 = obs[0, y, x], obs[1, y, x]
            out[0, y, x] = (a00 * o0 + a01 * o1) * inv
            out[1, y, x] = (a10 * o0 + a11 * o1) * inv
            if want_gain:
                gain[0, y, x] = np.sqrt(a00 * a00 + a01 * a01) * abs(inv)
                gain[1, y, x] = np.sqrt(a10 * a10 + a11 * a11) * abs(inv)
        singular[y] = bad


def unmix(views: np.ndarray, mixing: MixingField, *, colour_pattern=None,
          regularise: float = 0.0, noise_gain: bool = False) -> UnmixResult:
    """Solve ``views = M T`` per pixel for the clean views T.

    Parameters
    ----------
    views : (V, rows, cols) observed views (any linear unit), in ``mixing.views`` order;
        NaN in any view makes every output at that pixel NaN.
    mixing : the field M, of shape (rows, cols) and V views.
    colour_pattern : 2 x 2 indices into ``mixing.colours`` of pixels (0, 0), (0, 1), (1, 0),
        (1, 1) (a Bayer mosaic); None when the field has one colour.
    regularise : Tikhonov lambda (>= 0, in units of M, whose diagonal is ~1); 0 = exact inverse.
    noise_gain : also return the per-pixel noise gain of each output view.
    """
    obs = np.asarray(views)
    if obs.ndim != 3 or obs.shape[0] != mixing.n_views:
        raise ValueError(f"views must be ({mixing.n_views}, rows, cols) for this mixing, got "
                         f"shape {obs.shape}")
    if obs.shape[1:] != tuple(mixing.shape):
        raise ValueError(f"views are {obs.shape[1]} x {obs.shape[2]} but the mixing field is "
                         f"{mixing.shape[0]} x {mixing.shape[1]}")
    if not (np.isfinite(regularise) and 0 <= regularise <= MAX_REGULARISE):
        raise ValueError(f"regularise must be a number in [0, {MAX_REGULARISE:g}] (units of M, "
                         f"whose diagonal is 1; e.g. 0.05), got {regularise}")
    pattern = np.zeros((2, 2), np.int64)
    if colour_pattern is not None:
        pattern = np.asarray(colour_pattern, np.int64).reshape(2, 2)
    if pattern.min() < 0 or pattern.max() >= len(mixing.colours):
        raise ValueError(f"colour_pattern {pattern.tolist()} indexes colours outside "
                         f"{mixing.colours}")
    if colour_pattern is None and len(mixing.colours) != 1:
        raise ValueError(f"the mixing has colours {mixing.colours}: pass colour_pattern")
    if obs.dtype not in (np.float32, np.float64):
        obs = obs.astype(np.float32)
    nodes = np.ascontiguousarray(mixing.nodes, np.float64)
    if not np.isfinite(nodes).all():  # a NaN node would spread NaN over its whole tile
        raise ValueError("the mixing field holds non-finite values")
    r0, r1, wr = _axis_weights(np.asarray(mixing.node_rows, np.float64), obs.shape[1])
    c0, c1, wc = _axis_weights(np.asarray(mixing.node_cols, np.float64), obs.shape[2])
    out = np.empty(obs.shape, np.float32)
    gain = np.empty(obs.shape if noise_gain else (1, 1, 1), np.float32)
    singular = np.zeros(obs.shape[1], np.int64)
    if mixing.n_views == 2:
        _unmix2_kernel(obs, nodes, pattern, r0, r1, wr, c0, c1, wc, float(regularise) ** 2,
                       out, gain, noise_gain, singular)
    else:
        _unmix_kernel(obs, nodes, pattern, r0, r1, wr, c0, c1, wc, float(regularise) ** 2,
                      out, gain, noise_gain, singular)
    return UnmixResult(out, gain if noise_gain else None, int(singular.sum()))


def node_condition(mixing: MixingField) -> np.ndarray:
    """2-norm condition number of M at every node, (colours, node_rows, node_cols); inf where
    M is singular or not finite."""
    m = np.moveaxis(np.asarray(mixing.nodes, np.float64), (1, 2), (-2, -1))
    cond = np.full(m.shape[:-2], np.inf)
    finite = np.isfinite(m).all(axis=(-2, -1))
    if finite.any():
        s = np.linalg.svd(m[finite], compute_uv=False)
        with np.errstate(divide="ignore"):
            cond[finite] = np.where(s[:, -1] > 0, s[:, 0] / s[:, -1], np.inf)
    return cond


def predicted_noise_gain(mixing: MixingField, *, regularise: float = 0.0) -> np.ndarray:
    """Noise gain ||row_k(A)||_2 at every node, (colours, V, node_rows, node_cols)."""
    m = np.moveaxis(np.asarray(mixing.nodes, np.float64), (1, 2), (-2, -1))
    eye = np.eye(m.shape[-1])
    mt = np.swapaxes(m, -1, -2)
    a = np.linalg.solve(mt @ m + regularise ** 2 * eye, mt) if regularise else np.linalg.inv(m)
    return np.moveaxis(np.sqrt((a ** 2).sum(axis=-1)), -1, 1)


# ---------------------------------------------------------------------------------------------
# Light cannot be negative. A mixing that over-states the cross-talk (measured on another rig,
# or r too high) subtracts more of the other views than they gave: the clean views go below
# zero where a view is dark and the others bright, far beyond what noise explains. The noise of
# each input view is modelled from its level (the lower envelope, over blocks, of a robust
# noise measure: texture only raises a block's figure, so flat blocks of each level set it),
# carried to each output by its noise gain, and a tolerance of the mixing's own error (a share
# of the light it redistributes) is added. Noise is measured between the nearest pixels of one
# colour: sensor noise is alike at any distance, texture (blurred by optics) grows with it (the
# noise-free quad-pixel chart: 540-1380 DN between neighbours, 1490-3730 DN 2 px apart, on 3e4).
# Where an input view is itself below zero (a bias or refocus residue: no light) it is not judged.

NEGATIVE_SIGMA = 5.0  # Gaussian noise goes below -5 sigma once in 3.5 million pixels
MIXING_TOLERANCE = 0.02  # of the brightest view's level: 4 x the target error of a measured M
NEGATIVE_BLOCK = 32  # px (even: a Bayer block holds every colour)
NOISE_BINS = 8  # level bins of the noise model
NOISE_BLOCKS = 2000  # blocks sampled for the noise model (40 per level bin at least)
NOISE_QUANTILE = 20  # per cent: the blocks of a level bin that set its noise (the flat ones)


@dataclass(frozen=True)
class NegativeLight:
    """Per output view: ``share``, the largest share of one colour's known pixels (of all
    pixels for a view that is no mosaic) negative beyond noise and tolerance;
    ``worst_block``, the largest such share in one block, on either grid."""

    share: np.ndarray
    worst_block: np.ndarray


@numba.njit(cache=True)
def _block_noise(obs, j, y0, y1, x0, x1, lag, vals):
    """(median level, robust noise) of input view j in a block: 1.4826 x the median absolute
    second difference between pixels ``lag`` apart (the nearest of one colour: 2 in a mosaic,
    1 in a colour plane) / sqrt(1.5), the lesser of the two directions; NaN when the block has
    too few finite pixels."""
    rows, cols = obs.shape[1], obs.shape[2]
    best = np.inf
    for axis in range(2):
        m = 0
        for y in range(y0, y1):
            for x in range(x0, x1):
                if axis == 0 and lag <= x < cols - lag:
                    d = obs[j, y, x] - 0.5 * (obs[j, y, x - lag] + obs[j, y, x + lag])
                elif axis == 1 and lag <= y < rows - lag:
                    d = obs[j, y, x] - 0.5 * (obs[j, y - lag, x] + obs[j, y + lag, x])
                else:
                    continue
                if np.isfinite(d):
                    vals[m] = abs(d)
                    m += 1
        if m >= 16:
            best = min(best, 1.4826 * np.median(vals[:m]) / np.sqrt(1.5))
    m = 0
    for y in range(y0, y1):
        for x in range(x0, x1):
            if np.isfinite(obs[j, y, x]):
                vals[m] = obs[j, y, x]
                m += 1
    if m < 16 or not np.isfinite(best):
        return np.nan, np.nan
    return np.median(vals[:m]), best


@numba.njit(cache=True, parallel=True)
def _block_stats(obs, block, step, lag, level, noise):
    """Median level and robust noise of every input view in every ``step``-th block along each
    axis (numba, one block row per parallel task)."""
    rows, cols = obs.shape[1], obs.shape[2]
    for by in numba.prange(level.shape[1]):
        vals = np.empty(block * block)
        y0, y1 = by * step * block, min(rows, (by * step + 1) * block)
        for bx in range(level.shape[2]):
            x0, x1 = bx * step * block, min(cols, (bx * step + 1) * block)
            for j in range(obs.shape[0]):
                level[j, by, bx], noise[j, by, bx] = _block_noise(obs, j, y0, y1, x0, x1,
                                                                     lag, vals)


@numba.njit(cache=True, parallel=True)
def _negative_kernel(out, obs, gain, block, k_sigma, tol, xp, fp, below, known):
    """Per output view, colour and block: known pixels and those below -(k g sigma + tol L),
    with L the brightest input view at the pixel and sigma the largest of the input views'
    modelled noise (``xp``, ``fp``: level -> noise per input view); with ``k_sigma`` < 0 the
    bound is -tol L alone (the cheap pass).
    ``below``, ``known``: (V, colours, block rows, block cols), colours 4 for a 2 x 2 mosaic
    (counted by the pixel's place in it), else 1. One block row per parallel task."""
    v_out, rows, cols = out.shape
    mosaic = below.shape[1] == 4
    for by in numba.prange(below.shape[2]):
        y0, y1 = by * block, min(rows, (by + 1) * block)
        for bx in range(below.shape[3]):
            x0, x1 = bx * block, min(cols, (bx + 1) * block)
            for k in range(v_out):
                for y in range(y0, y1):
                    for x in range(x0, x1):
                        t = out[k, y, x]
                        if not np.isfinite(t):
                            continue
                        c = (y % 2) * 2 + x % 2 if mosaic else 0
                        known[k, c, by, bx] += 1
                        level, least, sigma = 0.0, np.inf, 0.0
                        for j in range(obs.shape[0]):
                            level = max(level, obs[j, y, x])
                            least = min(least, obs[j, y, x])
                        if least < 0.0 or t >= -tol * level:  # an input below 0 is no light
                            continue
                        if k_sigma >= 0.0:
                            for j in range(obs.shape[0]):
                                sigma = max(sigma, np.interp(obs[j, y, x], xp[j], fp[j]))
                            if t >= -(k_sigma * gain[k, y, x] * sigma + tol * level):
                                continue
                        below[k, c, by, bx] += 1


def _noise_model(obs: np.ndarray, block: int, lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Noise against level per input view, (V, NOISE_BINS) levels and noises: in each level
    bin (quantiles of the blocks' levels) the NOISE_QUANTILE-th percentile of the blocks'
    noise, made non-decreasing with level (shot noise grows with it)."""
    n_br, n_bc = -(-obs.shape[1] // block), -(-obs.shape[2] // block)
    step = max(1, int(np.sqrt(n_br * n_bc / NOISE_BLOCKS)))  # a sample of blocks suffices
    level = np.full((obs.shape[0], -(-n_br // step), -(-n_bc // step)), np.nan)
    noise = np.full_like(level, np.nan)
    _block_stats(obs, block, step, lag, level, noise)
    xp = np.zeros((obs.shape[0], NOISE_BINS))
    fp = np.zeros_like(xp)
    for j in range(obs.shape[0]):
        ok = np.isfinite(level[j]) & np.isfinite(noise[j])
        lv, nz = level[j][ok], noise[j][ok]
        if lv.size == 0:
            continue
        edges = np.quantile(lv, np.linspace(0, 1, NOISE_BINS + 1))
        idx = np.clip(np.searchsorted(edges, lv, side="right") - 1, 0, NOISE_BINS - 1)
        for b in range(NOISE_BINS):
            sel = idx == b
            xp[j, b] = np.median(lv[sel]) if sel.any() else edges[b]
            fp[j, b] = np.percentile(nz[sel], NOISE_QUANTILE) if sel.any() else 0.0
        order = np.argsort(xp[j], kind="stable")
        xp[j], fp[j] = xp[j][order], np.maximum.accumulate(fp[j][order])
    return xp, fp


def negative_light(solved: np.ndarray, observed: np.ndarray, gain: np.ndarray, *,
                   mosaic: bool = False, block: int = NEGATIVE_BLOCK,
                   k_sigma: float = NEGATIVE_SIGMA,
                   tolerance: float = MIXING_TOLERANCE) -> NegativeLight:
    """How far the unmixed views go below zero beyond what noise and the mixing's tolerance
    explain. ``solved``, ``observed``, ``gain``: (V, rows, cols) outputs, inputs and noise gain
    of one solve (the views in the mixing's order). A ``mosaic`` is counted colour by colour
    (a mixing too strong in one colour darkens a quarter of the pixels, never more than a
    quarter of a block), and the blocks on two grids half a block apart (an object across
    four blocks of one grid is inside one of the other's)."""
    out = np.ascontiguousarray(solved, np.float32)
    obs = np.ascontiguousarray(observed, np.float32)
    g = np.ascontiguousarray(gain, np.float32)
    # one pass counts cells of half a block; both grids' blocks are sums of 2 x 2 cells
    cell = block // 2
    shape = (out.shape[0], 4 if mosaic else 1, -(-out.shape[1] // cell), -(-out.shape[2] // cell))
    below, known = np.zeros(shape, np.int64), np.zeros(shape, np.int64)
    xp = np.zeros((obs.shape[0], 2))
    _negative_kernel(out, obs, g, cell, -1.0, tolerance, xp, xp, below, known)
    if below.any():  # the noise model only where a pixel is below the tolerance alone
        xp, fp = _noise_model(obs, block, 2 if mosaic else 1)
        below[:], known[:] = 0, 0
        _negative_kernel(out, obs, g, cell, k_sigma, tolerance, xp, fp, below, known)
    share = (below.sum(axis=(2, 3)) / np.maximum(known.sum(axis=(2, 3)), 1)).max(axis=1)
    worst = np.max([(b / np.maximum(k, 1)).max(axis=(1, 2, 3)) for b, k in
                    ((_blocks(below, shifted), _blocks(known, shifted))
                     for shifted in (False, True))], axis=0)
    return NegativeLight(share, worst)


def _blocks(cells: np.ndarray, shifted: bool) -> np.ndarray:
    """Counts per block of 2 x 2 cells (the last two axes), the grid starting a cell before the
    frame when ``shifted``."""
    pad = [(0, 0), (0, 0)] + [(int(shifted), (n + int(shifted)) % 2) for n in cells.shape[2:]]
    cells = np.pad(cells, pad)
    return cells[..., 0::2, 0::2] + cells[..., 1::2, 0::2] + cells[..., 0::2, 1::2] + \
        cells[..., 1::2, 1::2]
