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


def rcd(cfa: np.ndarray, pattern: str, *, scale: float | None = None) -> np.ndarray:
    """RGB (rows, cols, 3) float32 of a white-balanced Bayer mosaic ``cfa`` (rows, cols).

    ``scale``: the value taken as 1 inside the algorithm (its small constants assume data in
    [0, 1]); the frame's maximum by default. Banded callers pass the whole frame's.
    """
    data = np.asarray(cfa, np.float32)
    top = float(np.max(data)) if scale is None else float(scale)
    top = top if top > 0 else 1.0
    colours = np.array([["RGB".index(pattern[2 * r + c]) for c in range(2)] for r in range(2)],
                       np.int64)
    padded = np.pad(data * np.float32(1.0 / top), PAD, mode="reflect")
    out = _rcd(padded, colours)
    rgb = np.moveaxis(out[:, PAD:-PAD, PAD:-PAD], 0, -1)
    return np.ascontiguousarray(rgb) * np.float32(top)


def _rcd(cfa: np.ndarray, colours: np.ndarray) -> np.ndarray:
    """The four steps on a padded mosaic scaled to [0, 1] (negative noise clipped to 0, as the
    published algorithm's unsigned input); (3, rows, cols)."""
    out = _known(cfa, colours)
    vh_dir = _discrimination(cfa, 1, 0, 0, 1)
    _green(cfa, _lowpass(cfa, colours), vh_dir, colours, out)
    pq_dir = _discrimination(cfa, 1, 1, 1, -1)
    _red_blue_at_red_blue(pq_dir, colours, out)
    _red_blue_at_green(vh_dir, colours, out)
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _known(cfa, colours):
    rows, cols = cfa.shape
    out = np.zeros((3, rows, cols), np.float32)
    for r in numba.prange(rows):
        for c in range(cols):
            v = max(cfa[r, c], np.float32(0.0))
            cfa[r, c] = v
            out[colours[r & 1, c & 1], r, c] = v
    return out


@numba.njit(cache=True, parallel=True, fastmath=True)
def _lowpass(cfa, colours):
    rows, cols = cfa.shape
    lpf = np.zeros((rows, cols), np.float32)
    for r in numba.prange(1, rows - 1):
        for c in range(1, cols - 1):
            if colours[r & 1, c & 1] != 1:
                lpf[r, c] = (cfa[r, c]
                             + 0.5 * (cfa[r - 1, c] + cfa[r + 1, c] + cfa[r, c - 1] + cfa[r, c + 1])
                             + 0.25 * (cfa[r - 1, c - 1] + cfa[r - 1, c + 1]
                                       + cfa[r + 1, c - 1] + cfa[r + 1, c + 1]))
    return lpf


@numba.njit(cache=True, parallel=True, fastmath=True)
def _discrimination(cfa, dr1, dc1, dr2, dc2):
    """``A / (A + B)`` with A, B the squared 7-tap high-pass along (dr1, dc1) and (dr2, dc2),
    each summed over the pixel and its two neighbours along that axis."""
    rows, cols = cfa.shape
    a = np.zeros((rows, cols), np.float32)
    b = np.zeros((rows, cols), np.float32)
    for r in numba.prange(3, rows - 3):
        for c in range(3, cols - 3):
            a[r, c] = _hpf2(cfa, r, c, dr1, dc1)
            b[r, c] = _hpf2(cfa, r, c, dr2, dc2)
    out = np.full((rows, cols), np.float32(0.5))
    for r in numba.prange(4, rows - 4):
        for c in range(4, cols - 4):
            sa = max(_EPSSQ, a[r - dr1, c - dc1] + a[r, c] + a[r + dr1, c + dc1])
            sb = max(_EPSSQ, b[r - dr2, c - dc2] + b[r, c] + b[r + dr2, c + dc2])
            out[r, c] = sa / (sa + sb)
    return out


@numba.njit(cache=True, fastmath=True, inline="always")
def _hpf2(x, r, c, dr, dc):
    h = ((x[r - 3 * dr, c - 3 * dc] - x[r - dr, c - dc] - x[r + dr, c + dc]
          + x[r + 3 * dr, c + 3 * dc])
         - 3.0 * (x[r - 2 * dr, c - 2 * dc] + x[r + 2 * dr, c + 2 * dc]) + 6.0 * x[r, c])
    return h * h


@numba.njit(cache=True, fastmath=True, inline="always")
def _clearer(d, r, c):
    """The pixel's discrimination, or its diagonal neighbours' mean where that is further
    from 0.5 (a more decided direction)."""
    centre = d[r, c]
    around = 0.25 * (d[r - 1, c - 1] + d[r - 1, c + 1] + d[r + 1, c - 1] + d[r + 1, c + 1])
    return around if abs(0.5 - centre) < abs(0.5 - around) else centre


@numba.njit(cache=True, parallel=True, fastmath=True)
def _green(cfa, lpf, vh_dir, colours, out):
    rows, cols = cfa.shape
    for r in numba.prange(5, rows - 5):
        for c in range(5, cols - 5):
            if colours[r & 1, c & 1] == 1:
                continue
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
            n_est = x[r - 1, c] * 2.0 * here / (_EPS + here + lpf[r - 2, c])
            s_est = x[r + 1, c] * 2.0 * here / (_EPS + here + lpf[r + 2, c])
            w_est = x[r, c - 1] * 2.0 * here / (_EPS + here + lpf[r, c - 2])
            e_est = x[r, c + 1] * 2.0 * here / (_EPS + here + lpf[r, c + 2])
            v_est = (s_grad * n_est + n_grad * s_est) / (n_grad + s_grad)
            h_est = (w_grad * e_est + e_grad * w_est) / (e_grad + w_grad)
            disc = _clearer(vh_dir, r, c)
            out[1, r, c] = max(np.float32(0.0), disc * h_est + (1.0 - disc) * v_est)


@numba.njit(cache=True, parallel=True, fastmath=True)
def _red_blue_at_red_blue(pq_dir, colours, out):
    rows, cols = pq_dir.shape
    g = out[1]
    for r in numba.prange(7, rows - 7):
        for c in range(7, cols - 7):
            here = colours[r & 1, c & 1]
            if here == 1:
                continue
            x = out[2 - here]
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
            x[r, c] = max(np.float32(0.0), g[r, c] + (1.0 - disc) * p_est + disc * q_est)


@numba.njit(cache=True, parallel=True, fastmath=True)
def _red_blue_at_green(vh_dir, colours, out):
    rows, cols = vh_dir.shape
    g = out[1]
    for r in numba.prange(10, rows - 10):
        for c in range(10, cols - 10):
            if colours[r & 1, c & 1] != 1:
                continue
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
                x[r, c] = max(np.float32(0.0), g[r, c] + (1.0 - disc) * v_est + disc * h_est)
