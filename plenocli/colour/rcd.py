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

The interpolation steps compute a whole row (every column) into a buffer and keep the sites
they fill: a stride-1 loop vectorises, a stride-2 loop over one colour's sites does not, and
twice the arithmetic in 8 lanes is still about 2 x faster (docs/stitch.md, ninth round).
"""

from __future__ import annotations

import numba
import numpy as np

PAD = 12  # the steps reach 10 pixels in all: every output pixel sees real RCD support
_EPS = np.float32(1e-5)  # on data scaled to [0, 1], as in the published algorithm
_EPSSQ = np.float32(1e-10)
# float32 constants: a Python float would promote the kernels' arithmetic to float64
_HALF, _QUARTER, _ONE, _TWO, _THREE, _SIX = (np.float32(v) for v in (0.5, 0.25, 1, 2, 3, 6))


class Workspace:
    """Scratch arrays for mosaics of up to ``rows`` x ``cols``, reused band after band: fresh
    memory costs a page fault at first touch, as much time as the algorithm itself."""

    def __init__(self, rows: int, cols: int) -> None:
        shape = (rows + 2 * PAD, cols + 2 * PAD)
        self.cfa, self.lpf, self.vh_dir, self.pq_dir, self.a, self.b = (
            np.empty(shape, np.float32) for _ in range(6))
        self.planes = np.empty((3, *shape), np.float32)

    def fits(self, rows: int, cols: int) -> bool:
        return rows + 2 * PAD <= self.cfa.shape[0] and cols + 2 * PAD == self.cfa.shape[1]


def rcd(cfa: np.ndarray, pattern: str, *, scale: float | None = None, cfa_gains=None,
        channel_scale=(1.0, 1.0, 1.0), out: np.ndarray | None = None, first_row: int = 0,
        workspace: Workspace | None = None) -> np.ndarray:
    """RGB float32 of a white-balanced Bayer mosaic ``cfa`` (rows, cols), each channel
    multiplied by ``channel_scale`` (e.g. the inverse white-balance gains). ``cfa_gains``
    (2 x 2, per pixel of the pattern) balances a mosaic on the way in (``scale`` is then the
    balanced mosaic's).

    ``scale``: the value taken as 1 inside the algorithm (its small constants assume data in
    [0, 1]); the frame's maximum by default. Banded callers pass the whole frame's, an ``out``
    (n, cols, 3) that receives rows ``first_row`` to ``first_row + n`` of the result, and a
    :class:`Workspace` per thread. Returns ``out`` (default: all rows, (rows, cols, 3)).
    """
    data = np.ascontiguousarray(cfa, np.float32)
    rows, cols = data.shape
    top = float(np.max(data)) if scale is None else float(scale)
    top = top if top > 0 else 1.0
    gains = np.ones((2, 2), np.float32) if cfa_gains is None else np.asarray(cfa_gains, np.float32)
    colours = np.array([["RGB".index(pattern[2 * r + c]) for c in range(2)] for r in range(2)],
                       np.int64)
    if workspace is None or not workspace.fits(rows, cols):
        workspace = Workspace(rows, cols)
    if out is None:
        out = np.empty((rows, cols, 3), np.float32)
    if not 0 <= first_row <= rows - out.shape[0] or out.shape[1:] != (cols, 3):
        raise ValueError(f"out {out.shape} from row {first_row} does not fit {data.shape}")
    n = rows + 2 * PAD
    w = workspace
    cfa_p, planes = w.cfa[:n], w.planes[:, :n]
    _prepare(data, gains * np.float32(1.0 / top), colours, cfa_p, planes)
    _vh_dir(cfa_p, w.a[:n], w.b[:n], w.vh_dir[:n])
    _lowpass(cfa_p, colours, w.lpf[:n])
    _green(cfa_p, w.lpf[:n], w.vh_dir[:n], colours, planes)
    _pq_dir(cfa_p, colours, w.a[:n], w.b[:n], w.pq_dir[:n])
    _red_blue_at_red_blue(w.pq_dir[:n], colours, planes)
    _red_blue_at_green(w.vh_dir[:n], colours, planes)
    factors = np.asarray(channel_scale, np.float32) * np.float32(top)
    _interleave(planes, PAD + first_row, PAD, factors, out)
    return out


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _interleave(planes, row0, col0, factors, out):
    rows, cols, _ = out.shape
    for r in range(rows):
        for c in range(cols):
            for k in range(3):
                out[r, c, k] = planes[k, r + row0, c + col0] * factors[k]


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _prepare(data, factors, colours, cfa, planes):
    """The mosaic times ``factors`` (2 x 2, by CFA phase), negative noise clipped to 0 (the
    published algorithm works on unsigned data) and mirrored by PAD pixels (reflect-101: keeps
    the CFA phase), and the known samples in their colour planes (the others 0)."""
    rows, cols = data.shape
    for r in range(cfa.shape[0]):
        i = _reflect(r - PAD, rows)
        for c in range(cfa.shape[1]):
            j = _reflect(c - PAD, cols)
            v = max(data[i, j] * factors[i & 1, j & 1], np.float32(0.0))
            cfa[r, c] = v
            here = colours[r & 1, c & 1]
            for k in range(3):
                planes[k, r, c] = v if k == here else np.float32(0.0)


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _reflect(i, n):
    """Index ``i`` mirrored into [0, n) without repeating the edge (numpy's "reflect")."""
    if n == 1:
        return 0
    while i < 0 or i >= n:
        i = -i if i < 0 else 2 * (n - 1) - i
    return i


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _lowpass(cfa, colours, lpf):
    rows, cols = cfa.shape
    for r in range(1, rows - 1):
        for c in range(1, cols - 1):  # every column (green's are unused): it vectorises
            lpf[r, c] = (cfa[r, c]
                         + _HALF * (cfa[r - 1, c] + cfa[r + 1, c] + cfa[r, c - 1] + cfa[r, c + 1])
                         + _QUARTER * (cfa[r - 1, c - 1] + cfa[r - 1, c + 1]
                                   + cfa[r + 1, c - 1] + cfa[r + 1, c + 1]))


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _vh_dir(cfa, v, h, out):
    """Vertical/horizontal discrimination ``V / (V + H)``: the squared 7-tap high-pass along
    columns (V) and rows (H), each summed over the pixel and its two neighbours on that axis."""
    rows, cols = cfa.shape
    for r in range(3, rows - 3):  # one output row per loop, on row views: loops that vectorise
        vr, hr, x = v[r], h[r], cfa[r]
        up3, up2, up1, down1, down2, down3 = (cfa[r - 3], cfa[r - 2], cfa[r - 1], cfa[r + 1],
                                              cfa[r + 2], cfa[r + 3])
        for c in range(cols):
            e = (up3[c] - up1[c] - down1[c] + down3[c] - _THREE * (up2[c] + down2[c])
                 + _SIX * x[c])
            vr[c] = e * e
        for c in range(3, cols - 3):
            e = (x[c - 3] - x[c - 1] - x[c + 1] + x[c + 3] - _THREE * (x[c - 2] + x[c + 2])
                 + _SIX * x[c])
            hr[c] = e * e
    for r in range(4, rows - 4):
        above, here, below, hr, o = v[r - 1], v[r], v[r + 1], h[r], out[r]
        for c in range(4, cols - 4):
            sv = max(_EPSSQ, above[c] + here[c] + below[c])
            sh = max(_EPSSQ, hr[c - 1] + hr[c] + hr[c + 1])
            o[c] = sv / (sv + sh)


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _pq_dir(cfa, colours, p, q, out):
    """Diagonal discrimination ``P / (P + Q)``, built like :func:`_vh_dir` along the two
    diagonals (P: down-right, Q: down-left), at the red and blue pixels (the only ones that
    use it; their diagonal neighbours are red and blue too)."""
    rows, cols = cfa.shape
    for r in range(3, rows - 3):
        for c in range(3 + (colours[r & 1, 1] == 1), cols - 3, 2):
            p[r, c] = _hpf2(cfa, r, c, 1, 1)
            q[r, c] = _hpf2(cfa, r, c, 1, -1)
    for r in range(4, rows - 4):
        for c in range(4 + (colours[r & 1, 0] == 1), cols - 4, 2):
            sp = max(_EPSSQ, p[r - 1, c - 1] + p[r, c] + p[r + 1, c + 1])
            sq = max(_EPSSQ, q[r - 1, c + 1] + q[r, c] + q[r + 1, c - 1])
            out[r, c] = sp / (sp + sq)


@numba.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _hpf2(x, r, c, dr, dc):
    h = ((x[r - 3 * dr, c - 3 * dc] - x[r - dr, c - dc] - x[r + dr, c + dc]
          + x[r + 3 * dr, c + 3 * dc])
         - _THREE * (x[r - 2 * dr, c - 2 * dc] + x[r + 2 * dr, c + 2 * dc]) + _SIX * x[r, c])
    return h * h


@numba.njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _clearer(d, r, c):
    """The pixel's discrimination, or its diagonal neighbours' mean where that is further
    from 0.5 (a more decided direction)."""
    centre = d[r, c]
    around = _QUARTER * (d[r - 1, c - 1] + d[r - 1, c + 1] + d[r + 1, c - 1] + d[r + 1, c + 1])
    return around if abs(_HALF - centre) < abs(_HALF - around) else centre


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _green(cfa, lpf, vh_dir, colours, out):
    rows, cols = cfa.shape
    row = np.empty(cols, np.float32)
    for r in range(5, rows - 5):
        first = 5 + (colours[r & 1, 1] == 1)  # the first red or blue column from 5
        for c in range(5, cols - 5):  # every column into the buffer, red and blue kept
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
            row[c] = max(np.float32(0.0), disc * h_est + (_ONE - disc) * v_est)
        g = out[1, r]
        for c in range(first, cols - 5, 2):
            g[c] = row[c]


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _red_blue_at_red_blue(pq_dir, colours, out):
    rows, cols = pq_dir.shape
    g = out[1]
    row = np.empty(cols, np.float32)
    for r in range(7, rows - 7):
        first = 7 + (colours[r & 1, 1] == 1)
        x = out[2 - colours[r & 1, first & 1]]  # blue on red rows, red on blue rows
        for c in range(7, cols - 7):
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
            row[c] = max(np.float32(0.0), g[r, c] + (_ONE - disc) * p_est + disc * q_est)
        xr = x[r]
        for c in range(first, cols - 7, 2):
            xr[c] = row[c]


@numba.njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _red_blue_at_green(vh_dir, colours, out):
    rows, cols = vh_dir.shape
    g = out[1]
    row = np.empty(cols, np.float32)
    for r in range(10, rows - 10):
        first = 10 + (colours[r & 1, 0] != 1)  # the first green column from 10
        for k in (0, 2):
            x = out[k]
            for c in range(10, cols - 10):
                disc = _clearer(vh_dir, r, c)
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
                row[c] = max(np.float32(0.0), g[r, c] + (_ONE - disc) * v_est + disc * h_est)
            xr = x[r]
            for c in range(first, cols - 10, 2):
                xr[c] = row[c]
