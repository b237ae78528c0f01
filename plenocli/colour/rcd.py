"""Ratio Corrected Demosaicing (RCD, Luis Sanz Rodriguez, v2.3), in numba.

RCD is the default demosaic of RawTherapee and darktable. Written here from the published
description of its steps:

1. Direction: a 7-tap high-pass filter of the mosaic along columns and along rows, squared and
   summed over three pixels, gives the vertical/horizontal discrimination ``V / (V + H)``.
2. A 3 x 3 low-pass of the mosaic (all colours) at the red and blue pixels.
3. Green at red and blue pixels: each of the four cardinal green neighbours is scaled by the
   ratio of the low-pass here and two pixels further on (the "ratio correction"), the two
   estimates of each axis are weighted by the inverse of their gradients, and the axes are
   mixed by the direction of step 1 (or its diagonal neighbours' mean where that is clearer).
4. Red at blue pixels and blue at red pixels from the colour differences of the four diagonal
   neighbours, the diagonals mixed by a diagonal discrimination built like step 1; then red
   and blue at green pixels from the cardinal colour differences, mixed by step 1's direction.

Colour differences and ratios assume white-balanced channels (``plenocli.colour.demosaic``
balances the mosaic before calling). The mosaic is mirrored by :data:`PAD` pixels (reflect-101
keeps the CFA phase) so that every output pixel is computed by the full algorithm.
"""

from __future__ import annotations

import numba
import numpy as np

PAD = 12  # the steps reach 10 pixels in all: every output pixel sees real RCD support
_EPS = np.float32(1e-5)  # on data scaled to [0, 1], as in the published algorithm
_EPSSQ = np.float32(1e-10)
# float32 constants: a Python float would promote the kernels' arithmetic to float64
_HALF, _QUARTER, _ONE, _TWO, _THREE, _SIX = (np.float32(v) for v in (0.5, 0.25, 1, 2, 3, 6))


def rcd(cfa: np.ndarray, pattern: str, *, scale: float | None = None,
        channel_scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    """RGB (rows, cols, 3) float32 of a white-balanced Bayer mosaic ``cfa`` (rows, cols),
    each channel multiplied by ``channel_scale`` (e.g. the inverse white-balance gains).

    ``scale``: the value taken as 1 inside the algorithm (its small constants assume data in
    [0, 1]); the frame's maximum by default. Banded callers pass the whole frame's.
    """
    data = np.asarray(cfa, np.float32)
    top = float(np.max(data)) if scale is None else float(scale)
    top = top if top > 0 else 1.0
    colours = np.array([["RGB".index(pattern[2 * r + c]) for c in range(2)] for r in range(2)],
                       np.int64)
    padded = np.pad(data * np.float32(1.0 / top), PAD, mode="reflect")
    planes = _rcd(padded, colours)
    factors = np.asarray(channel_scale, np.float32) * np.float32(top)
    return _interleave(planes, PAD, factors)


def _rcd(cfa: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """The four steps on a padded mosaic scaled to [0, 1] (negative noise clipped to 0, as the
    published algorithm's unsigned input); (3, rows, cols)."""
    out = _known(cfa, colours)
    vh_dir = _vh_dir(cfa)
    _green(cfa, _lowpass(cfa, colours), vh_dir, colours, out)
    pq_dir = _pq_dir(cfa, colours)
    _red_blue_at_red_blue(pq_dir, colours, out)
    _red_blue_at_green(vh_dir, colours, out)
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _interleave(planes, pad, factors):
    _, rows, cols = planes.shape
    out = np.empty((rows - 2 * pad, cols - 2 * pad, 3), np.float32)
    for r in numba.prange(rows - 2 * pad):
        for c in range(cols - 2 * pad):
            for k in range(3):
                out[r, c, k] = planes[k, r + pad, c + pad] * factors[k]
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _known(cfa, colours):
    rows, cols = cfa.shape
    out = np.empty((3, rows, cols), np.float32)
    for r in numba.prange(rows):
        for c in range(cols):
            v = max(cfa[r, c], np.float32(0.0))
            cfa[r, c] = v
            here = colours[r & 1, c & 1]
            for k in range(3):
                out[k, r, c] = v if k == here else np.float32(0.0)
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _lowpass(cfa, colours):
    rows, cols = cfa.shape
    lpf = np.zeros((rows, cols), np.float32)
    for r in numba.prange(1, rows - 1):
        for c in range(1 + (colours[r & 1, 1] == 1), cols - 1, 2):  # red and blue columns
            lpf[r, c] = (cfa[r, c]
                         + _HALF * (cfa[r - 1, c] + cfa[r + 1, c] + cfa[r, c - 1] + cfa[r, c + 1])
                         + _QUARTER * (cfa[r - 1, c - 1] + cfa[r - 1, c + 1]
                                   + cfa[r + 1, c - 1] + cfa[r + 1, c + 1]))
    return lpf


@numba.njit(cache=True, parallel=True, fastmath=True)
def _vh_dir(cfa):
    """Vertical/horizontal discrimination ``V / (V + H)``: the squared 7-tap high-pass along
    columns (V) and rows (H), each summed over the pixel and its two neighbours on that axis."""
    rows, cols = cfa.shape
    v = np.zeros((rows, cols), np.float32)
    h = np.zeros((rows, cols), np.float32)
    for r in numba.prange(3, rows - 3):
        for c in range(3, cols - 3):
            v[r, c] = _hpf2(cfa, r, c, 1, 0)
            h[r, c] = _hpf2(cfa, r, c, 0, 1)
    out = np.full((rows, cols), np.float32(0.5))
    for r in numba.prange(4, rows - 4):
        for c in range(4, cols - 4):
            sv = max(_EPSSQ, v[r - 1, c] + v[r, c] + v[r + 1, c])
            sh = max(_EPSSQ, h[r, c - 1] + h[r, c] + h[r, c + 1])
            out[r, c] = sv / (sv + sh)
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _pq_dir(cfa, colours):
    """Diagonal discrimination ``P / (P + Q)``, built like :func:`_vh_dir` along the two
    diagonals (P: down-right, Q: down-left), at the red and blue pixels (the only ones that
    use it; their diagonal neighbours are red and blue too)."""
    rows, cols = cfa.shape
    p = np.zeros((rows, cols), np.float32)
    q = np.zeros((rows, cols), np.float32)
    for r in numba.prange(3, rows - 3):
        for c in range(3 + (colours[r & 1, 1] == 1), cols - 3, 2):
            p[r, c] = _hpf2(cfa, r, c, 1, 1)
            q[r, c] = _hpf2(cfa, r, c, 1, -1)
    out = np.full((rows, cols), np.float32(0.5))
    for r in numba.prange(4, rows - 4):
        for c in range(4 + (colours[r & 1, 0] == 1), cols - 4, 2):
            sp = max(_EPSSQ, p[r - 1, c - 1] + p[r, c] + p[r + 1, c + 1])
            sq = max(_EPSSQ, q[r - 1, c + 1] + q[r, c] + q[r + 1, c - 1])
            out[r, c] = sp / (sp + sq)
    return out


@numba.njit(cache=True, fastmath=True, inline="always")
def _hpf2(x, r, c, dr, dc):
    h = ((x[r - 3 * dr, c - 3 * dc] - x[r - dr, c - dc] - x[r + dr, c + dc]
          + x[r + 3 * dr, c + 3 * dc])
         - _THREE * (x[r - 2 * dr, c - 2 * dc] + x[r + 2 * dr, c + 2 * dc]) + _SIX * x[r, c])
    return h * h


@numba.njit(cache=True, fastmath=True, inline="always")
def _clearer(d, r, c):
    """The pixel's discrimination, or its diagonal neighbours' mean where that is further
    from 0.5 (a more decided direction)."""
    centre = d[r, c]
    around = _QUARTER * (d[r - 1, c - 1] + d[r - 1, c + 1] + d[r + 1, c - 1] + d[r + 1, c + 1])
    return around if abs(_HALF - centre) < abs(_HALF - around) else centre


@numba.njit(cache=True, parallel=True, fastmath=True)
def _green(cfa, lpf, vh_dir, colours, out):
    rows, cols = cfa.shape
    for r in numba.prange(5, rows - 5):
        first = 5 + (colours[r & 1, 1] == 1)  # the first red or blue column from 5
        for c in range(first, cols - 5, 2):
            x = cfa
            n_grad = (_EPS + abs(x[r - 1, c] - x[r + 1, c]) + abs(x[r, c] - x[r - 2, c])
                      + abs(x[r - 1, c] - x[r - 3, c]) + abs(x[r - 2, c] - x[r - 4, c]))
            s_grad = (_EPS + abs(x[r - 1, c] - x[r + 1, c]) + abs(x[r, c] - x[r + 2, c])
                      + abs(x[r + 1, c] - x[r + 3, c]) + abs(x[r + 2, c] - x[r + 4, c]))
            w_grad = (_EPS + abs(x[r, c - 1] - x[r, c + 1]) + abs(x[r, c] - x[r, c - 2])
                      + abs(x[r, c - 1] - x[r, c - 3]) + abs(x[r, c - 2] - x[r, c - 4]))
            e_grad = (_EPS + abs(x[r, c - 1] - x[r, c + 1]) + abs(x[r, c] - x[r, c + 2])
                      + abs(x[r, c + 1] - x[r, c + 3]) + abs(x[r, c + 2] - x[r, c + 4]))
            here = lpf[r, c]
            n_est = x[r - 1, c] * _TWO * here / (_EPS + here + lpf[r - 2, c])
            s_est = x[r + 1, c] * _TWO * here / (_EPS + here + lpf[r + 2, c])
            w_est = x[r, c - 1] * _TWO * here / (_EPS + here + lpf[r, c - 2])
            e_est = x[r, c + 1] * _TWO * here / (_EPS + here + lpf[r, c + 2])
            v_est = (s_grad * n_est + n_grad * s_est) / (n_grad + s_grad)
            h_est = (w_grad * e_est + e_grad * w_est) / (e_grad + w_grad)
            disc = _clearer(vh_dir, r, c)
            out[1, r, c] = max(np.float32(0.0), disc * h_est + (_ONE - disc) * v_est)


@numba.njit(cache=True, parallel=True, fastmath=True)
def _red_blue_at_red_blue(pq_dir, colours, out):
    rows, cols = pq_dir.shape
    g = out[1]
    for r in numba.prange(7, rows - 7):
        first = 7 + (colours[r & 1, 1] == 1)
        x = out[2 - colours[r & 1, first & 1]]  # blue on red rows, red on blue rows
        for c in range(first, cols - 7, 2):
            nw_grad = (_EPS + abs(x[r - 1, c - 1] - x[r + 1, c + 1])
                       + abs(x[r - 1, c - 1] - x[r - 3, c - 3]) + abs(g[r, c] - g[r - 2, c - 2]))
            ne_grad = (_EPS + abs(x[r - 1, c + 1] - x[r + 1, c - 1])
                       + abs(x[r - 1, c + 1] - x[r - 3, c + 3]) + abs(g[r, c] - g[r - 2, c + 2]))
            sw_grad = (_EPS + abs(x[r - 1, c + 1] - x[r + 1, c - 1])
                       + abs(x[r + 1, c - 1] - x[r + 3, c - 3]) + abs(g[r, c] - g[r + 2, c - 2]))
            se_grad = (_EPS + abs(x[r - 1, c - 1] - x[r + 1, c + 1])
                       + abs(x[r + 1, c + 1] - x[r + 3, c + 3]) + abs(g[r, c] - g[r + 2, c + 2]))
            nw_est = x[r - 1, c - 1] - g[r - 1, c - 1]
            ne_est = x[r - 1, c + 1] - g[r - 1, c + 1]
            sw_est = x[r + 1, c - 1] - g[r + 1, c - 1]
            se_est = x[r + 1, c + 1] - g[r + 1, c + 1]
            p_est = (nw_grad * se_est + se_grad * nw_est) / (nw_grad + se_grad)
            q_est = (ne_grad * sw_est + sw_grad * ne_est) / (ne_grad + sw_grad)
            disc = _clearer(pq_dir, r, c)
            x[r, c] = max(np.float32(0.0), g[r, c] + (_ONE - disc) * p_est + disc * q_est)


@numba.njit(cache=True, parallel=True, fastmath=True)
def _red_blue_at_green(vh_dir, colours, out):
    rows, cols = vh_dir.shape
    g = out[1]
    for r in numba.prange(10, rows - 10):
        for c in range(10 + (colours[r & 1, 0] != 1), cols - 10, 2):  # the green columns
            disc = _clearer(vh_dir, r, c)
            for k in (0, 2):
                x = out[k]
                n_grad = (_EPS + abs(g[r, c] - g[r - 2, c]) + abs(x[r - 1, c] - x[r + 1, c])
                          + abs(x[r - 1, c] - x[r - 3, c]))
                s_grad = (_EPS + abs(g[r, c] - g[r + 2, c]) + abs(x[r + 1, c] - x[r - 1, c])
                          + abs(x[r + 1, c] - x[r + 3, c]))
                w_grad = (_EPS + abs(g[r, c] - g[r, c - 2]) + abs(x[r, c - 1] - x[r, c + 1])
                          + abs(x[r, c - 1] - x[r, c - 3]))
                e_grad = (_EPS + abs(g[r, c] - g[r, c + 2]) + abs(x[r, c + 1] - x[r, c - 1])
                          + abs(x[r, c + 1] - x[r, c + 3]))
                n_est = x[r - 1, c] - g[r - 1, c]
                s_est = x[r + 1, c] - g[r + 1, c]
                w_est = x[r, c - 1] - g[r, c - 1]
                e_est = x[r, c + 1] - g[r, c + 1]
                v_est = (n_grad * s_est + s_grad * n_est) / (n_grad + s_grad)
                h_est = (e_grad * w_est + w_grad * e_est) / (e_grad + w_grad)
                x[r, c] = max(np.float32(0.0), g[r, c] + (_ONE - disc) * v_est + disc * h_est)
