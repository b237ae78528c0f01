"""Refocusing a focused (type-2) plenoptic capture by Lanczos splatting (paper Eq. 3).

Every sensor pixel (x, y) of micro-image (i, j), centred at c_ij, is projected to::

    (X, Y) = s * (g * ((x, y) - c_ij) + c_ij)

in the refocused image and splatted there with a separable kernel (Lanczos a = 2, 3, 4, or
bilinear for comparison) into a sum image and a weight map; the image is sum / weight at the
end. ``s`` is the size of the refocused image relative to the sensor image, ``g`` selects the
refocus plane. Each pixel's kernel taps are normalised to sum to 1 (a partition of unity), so
the weight map counts samples and splatting conserves flux: sum(image * weight) is the sum of
the splatted pixels (away from the borders).

c_ij is the centre of the micro-image holding the pixel: the nearest lattice centre of the
:class:`LensGrid` (same rule as ``LensGrid.nearest_index``), replaced by the
refined centre of that lens when the grid has one.

Views select pixels by their offset (dx, dy) = (x, y) - c_ij from the micro-image centre (y down):
``full`` keeps all, ``left``/``right`` keep dx < -m/2 / dx > m/2 (paper: m = 2, the mask
width that cancels sub-aperture cross-talk), ``top``/``bottom`` keep dy < -m/2 / dy > m/2 and
the quadrants ``qRC`` (row R, column C: q00 top-left, q01 top-right, q10 bottom-left, q11
bottom-right) combine both. ``radius`` additionally keeps only pixels with |d| <= radius.

Bayer input: each CFA colour is splatted into its own channel with its own weight map (no
demosaicing); the result has three channels R, G, B.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from plenocli.model.cfa import check_pattern
from plenocli.model.focus import (  # noqa: F401 (re-exported)
    KERNELS,
    MAX_G_VALUES,
    MAX_S,
    VIEWS,
    check_mask_width,
    parse_g,
)
from plenocli.model.lensgrid import LensGrid

CHANNELS = "RGB"
MIN_OUTPUT_SIDE = 4          # fewer refocused pixels a side hold no picture and no sharpness
MAX_OUTPUT_PIXELS = 2 ** 28  # ~268 Mpx per channel: far beyond any sensor at s <= 1
MAX_STACK_PIXELS = 2 ** 31   # a whole sweep's pages together: 8 GiB of float32
# Voronoi-cell circumradius / pitch: no pixel is farther than this from its nearest lattice centre.
_CELL_RADIUS = {"hex": 1.0 / math.sqrt(3.0), "square": 1.0 / math.sqrt(2.0)}


# --------------------------------------------------------------------------- compiled kernel
LUT_BINS = 4096  # sub-pixel positions of the tabulated kernel: 1/4096 px, far below any effect


def kernel_table(a: int, bins: int = LUT_BINS) -> np.ndarray:
    """Tap weights for fractional positions f = k / bins, k = 0 .. bins: shape (bins + 1, 2a).

    Row k holds the weights of taps floor(pos) - a + 1 .. floor(pos) + a for a sample at
    pos = floor(pos) + f, normalised to sum 1 (partition of unity, hence flux conservation).
    Lanczos: L(t) = sinc(t) sinc(t / a) for |t| < a; ``a = 1`` is the bilinear (tent) kernel.
    """
    f = np.arange(bins + 1)[:, None] / bins
    m = np.arange(-a + 1, a + 1)[None, :]
    t = f - m
    w = np.maximum(1.0 - np.abs(t), 0.0) if a == 1 else np.sinc(t) * np.sinc(t / a)
    return w / w.sum(axis=1, keepdims=True)


@njit(cache=True, inline="always")
def _flush(line, lo, hi, n2, table, Y, bins, half, out_r0, out_r1, off, buf):
    """Splat the X-splatted run ``line[lo:hi]`` into the ``buf`` rows around ``Y``; clear it."""
    by = math.floor(Y)
    fy = int((Y - by) * bins + 0.5)
    ky0 = int(by) - half + 1
    ntap = table.shape[1]
    for ky in range(max(0, out_r0 - ky0), min(ntap, out_r1 - ky0)):
        brow = ky0 + ky + off
        wy = table[fy, ky]
        for col in range(lo, hi):
            for q in range(n2):
                buf[brow, col, q] += wy * line[col, q]
    for col in range(lo, hi):
        for q in range(n2):
            line[col, q] = 0.0


@njit(cache=True, parallel=True)
def _splat(frame, x0, y0, inv, basis, offset, cx_tab, cy_tab, imin, jmin, s, g,  # noqa: C901, PLR0915 (numba kernel)
           xsign, ysign, half_mask, radius2, chan_map, table, band_rows, band_out, buf_off,
           buf, rows_out, cols_out, g_tab, g_imin, g_jmin):
    """Splat ``frame`` into ``buf`` (total band rows, cols_out, 2 * channels).

    The last axis interleaves (sum of w * value, sum of w) per channel. Separable splatting:
    along one sensor row, the pixels of one micro-image share c_ij and y, hence the same output
    Y; such a run is first splatted along X into a line buffer, and the line is then splatted
    along Y once. This gives the same sums as per-pixel 2-D splatting (up to rounding) for a
    fraction of the memory traffic.

    The input rows are cut into fixed bands (``band_rows[k]`` .. ``band_rows[k + 1]``), each
    with its own slice of ``buf`` (output rows ``band_out[k]`` .. ``band_out[n + k]``, buffer
    rows from ``buf_off[k]``), so bands run in parallel without races and the merge order, hence
    the result, does not depend on the number of threads. ``g_tab[i - g_imin, j - g_jmin]``,
    where finite, is lens (i, j)'s own g (all-in-focus); other lenses use ``g``.
    """
    n_bands = band_rows.shape[0] - 1
    cols = frame.shape[1]
    n2 = buf.shape[2]
    ntap = table.shape[1]
    half = ntap // 2
    bins = table.shape[0] - 1
    ni, nj = cx_tab.shape
    pitch2 = basis[0, 0] ** 2 + basis[0, 1] ** 2
    inner2 = 0.25 * pitch2 * (1.0 - 1e-9)
    for band in prange(n_bands):
        out_r0 = max(band_out[band], 0)
        out_r1 = min(band_out[n_bands + band], rows_out)  # exclusive
        off = buf_off[band] - band_out[band]
        line = np.zeros((cols_out, n2))
        gl = g
        for r in range(band_rows[band], band_rows[band + 1]):
            y = r + y0
            run_i = -(1 << 62)
            run_j = 0
            bi = 0
            bj = 0
            lat_x = 1e300  # no current lens: forces a search at the first pixel
            lat_y = 1e300
            run_y = 0.0
            lo = cols_out
            hi = 0
            for c in range(cols):
                x = c + x0
                # nearest lattice centre. Inside the circle of radius pitch / 2 around the
                # current lens's lattice centre no other lattice point can be nearer (lattice
                # points are >= pitch apart): ~90 % of pixels skip the search.
                ex = x - lat_x
                ey = y - lat_y
                if ex * ex + ey * ey >= inner2:
                    dxo = x - offset[0]
                    dyo = y - offset[1]
                    i0 = math.floor(inv[0, 0] * dxo + inv[0, 1] * dyo)
                    j0 = math.floor(inv[1, 0] * dxo + inv[1, 1] * dyo)
                    best = 1e300
                    for di in range(2):  # the nearest is a corner of the enclosing lattice cell
                        for dj in range(2):
                            px = (i0 + di) * basis[0, 0] + (j0 + dj) * basis[1, 0] - dxo
                            py = (i0 + di) * basis[0, 1] + (j0 + dj) * basis[1, 1] - dyo
                            d2 = px * px + py * py
                            if d2 < best:
                                best = d2
                                bi = int(i0) + di
                                bj = int(j0) + dj
                    lat_x = offset[0] + bi * basis[0, 0] + bj * basis[1, 0]
                    lat_y = offset[1] + bi * basis[0, 1] + bj * basis[1, 1]
                cx = lat_x
                cy = lat_y
                ti = bi - imin
                tj = bj - jmin
                if 0 <= ti < ni and 0 <= tj < nj and math.isfinite(cx_tab[ti, tj]):
                    cx = cx_tab[ti, tj]
                    cy = cy_tab[ti, tj]
                dy = y - cy
                if bi != run_i or bj != run_j:  # a new micro-image: flush the previous run
                    if hi > lo:
                        _flush(line, lo, hi, n2, table, run_y, bins, half, out_r0, out_r1,
                               off, buf)
                    lo = cols_out
                    hi = 0
                    run_i = bi
                    run_j = bj
                    gl = g
                    gi = bi - g_imin
                    gj = bj - g_jmin
                    if 0 <= gi < g_tab.shape[0] and 0 <= gj < g_tab.shape[1] and \
                            math.isfinite(g_tab[gi, gj]):
                        gl = g_tab[gi, gj]
                    run_y = s * (gl * dy + cy)
                ch = chan_map[r & 1, c & 1]
                if ch < 0:
                    continue
                v = frame[r, c]
                if not math.isfinite(v):
                    continue
                dx = x - cx
                if xsign < 0 and not dx < -half_mask:
                    continue
                if xsign > 0 and not dx > half_mask:
                    continue
                if ysign < 0 and not dy < -half_mask:
                    continue
                if ysign > 0 and not dy > half_mask:
                    continue
                if radius2 >= 0.0 and dx * dx + dy * dy > radius2:
                    continue
                X = s * (gl * dx + cx)
                bx = math.floor(X)
                fx = int((X - bx) * bins + 0.5)
                kx0 = int(bx) - half + 1
                kx_lo = max(0, -kx0)
                kx_hi = min(ntap, cols_out - kx0)
                if kx_hi <= kx_lo:
                    continue
                c2 = 2 * ch
                for kx in range(kx_lo, kx_hi):
                    w = table[fx, kx]
                    line[kx0 + kx, c2] += w * v
                    line[kx0 + kx, c2 + 1] += w
                lo = min(lo, kx0 + kx_lo)
                hi = max(hi, kx0 + kx_hi)
            if hi > lo:
                _flush(line, lo, hi, n2, table, run_y, bins, half, out_r0, out_r1, off, buf)


# --------------------------------------------------------------------------- public API
def output_shape(shape: tuple[int, int], s: float) -> tuple[int, int]:
    """(rows_out, cols_out) of the refocused image of a (rows, cols) frame at scale ``s``.

    Output pixel (R, C) is centred at (X, Y) = (C, R); the frame's pixel centres span
    [0, s * (size - 1)].
    """
    return int(math.floor(s * (shape[0] - 1))) + 1, int(math.floor(s * (shape[1] - 1))) + 1


def centre_table(grid: LensGrid) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Refined centres as dense tables indexed by lattice (i - imin, j - jmin).

    Returns (cx, cy, imin, jmin); entries without a refined centre are NaN (the kernel then
    uses the lattice centre). A grid without refined centres gives 1 x 1 NaN tables.
    """
    if grid.centres_xy is None or len(grid.centres_xy) == 0:
        nan = np.full((1, 1), np.nan)
        return nan, nan.copy(), 0, 0
    idx = np.asarray(grid.indices, np.int64)
    xy = np.asarray(grid.centres_xy, float)
    imin, jmin = idx.min(axis=0)
    ni, nj = idx.max(axis=0) - (imin, jmin) + 1
    cx = np.full((ni, nj), np.nan)
    cy = np.full((ni, nj), np.nan)
    cx[idx[:, 0] - imin, idx[:, 1] - jmin] = xy[:, 0]
    cy[idx[:, 0] - imin, idx[:, 1] - jmin] = xy[:, 1]
    return cx, cy, int(imin), int(jmin)


def _check(frame, grid, s, g, view, mask_width, kernel, radius, cfa, min_weight):
    if not isinstance(grid, LensGrid):
        raise TypeError(f"grid must be a LensGrid, got {type(grid).__name__}")
    if frame.ndim != 2:
        raise ValueError(f"frame must be 2-D (rows, cols), got shape {frame.shape}")
    check_options(s=s, g=g, view=view, mask_width=mask_width, kernel=kernel, radius=radius,
                  cfa=cfa, min_weight=min_weight)
    if view != "full":
        check_mask_width(mask_width, grid.pitch_px)
    check_output_size(frame.shape, s)


def check_output_size(shape: tuple[int, int], s: float, *, pages: int = 1) -> None:
    """Raise ValueError, before anything is allocated, when a (rows, cols) frame refocused at
    scale ``s`` would be absurdly large: more than MAX_OUTPUT_PIXELS per page, or more than
    MAX_STACK_PIXELS for all ``pages`` of a sweep (g values x channels)."""
    rows_out, cols_out = output_shape(shape, s)
    if min(rows_out, cols_out) < MIN_OUTPUT_SIDE:
        raise ValueError(f"s = {s:g} makes a {cols_out} x {rows_out} image from a "
                         f"{shape[1]} x {shape[0]} frame; s is the output size relative to the "
                         f"sensor image (paper: 0.2): use an s that gives at least "
                         f"{MIN_OUTPUT_SIDE} pixels a side")
    if rows_out * cols_out > MAX_OUTPUT_PIXELS:
        raise ValueError(f"s = {s:g} makes a {cols_out} x {rows_out} image from a "
                         f"{shape[1]} x {shape[0]} frame; s is the output size relative to the "
                         "sensor image (paper: 0.2): use s <= 1")
    if pages * rows_out * cols_out > MAX_STACK_PIXELS:
        raise ValueError(f"{pages} pages of {cols_out} x {rows_out} pixels are more than "
                         f"{MAX_STACK_PIXELS * 4 / 2 ** 30:g} GiB; sweep fewer g values or "
                         "use a smaller s")


def check_options(*, s: float, g: float, view: str, mask_width: float, kernel: str,
                  radius: float | None, cfa: str | None, min_weight: float) -> None:
    """Raise ValueError naming the first refocus option that is out of range."""
    if not (np.isfinite(s) and s > 0):
        raise ValueError(f"s must be a positive number (paper: 0.2), got {s}")
    if s > MAX_S:   # each output pixel gets 1 / s^2 sensor samples on average: below 1, holes
        raise ValueError(f"s = {s:g} asks for more output pixels than the sensor has samples "
                         "(1 / s^2 per output pixel): use s <= 1 (paper: 0.2)")
    if not (np.isfinite(g) and g != 0):
        raise ValueError(f"g must be a finite non-zero number (paper: 4; negative for a "
                         f"Galilean camera's inverted micro-images), got {g}")
    if view not in VIEWS:
        raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
    if kernel not in KERNELS:
        raise ValueError(f"kernel must be one of {', '.join(KERNELS)}, got {kernel!r}")
    if not (np.isfinite(mask_width) and mask_width >= 0):
        raise ValueError(f"mask_width must be >= 0 pixels (paper: 2), got {mask_width}")
    if radius is not None and not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number of pixels, got {radius}")
    if not (np.isfinite(min_weight) and min_weight >= 0):
        raise ValueError(f"min_weight must be >= 0, got {min_weight}")
    if cfa is not None:
        check_pattern(cfa)


def splat_sums(frame: np.ndarray, grid: LensGrid, *, s: float = 0.2, g: float = 4.0,
               view: str = "full", mask_width: float = 2.0, kernel: str = "lanczos3",
               radius: float | None = None, cfa: str | None = None,
               bands: int | None = None, lens_g: tuple[np.ndarray, int, int] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """The raw splatting sums of Eq. 3: (sum of w * value, sum of w), each (channels, R, C).

    ``channels`` is 3 (R, G, B) when ``cfa`` is given, else 1. Parameters as in :func:`refocus`;
    ``bands`` fixes the number of parallel row bands (default: from the frame size only, so
    results never depend on the number of threads); ``lens_g`` as in :func:`refocus`.
    """
    frame = np.asarray(frame)
    _check(frame, grid, s, g, view, mask_width, kernel, radius, cfa, 0.0)
    data = np.ascontiguousarray(frame, dtype=np.float32)
    rows, cols = data.shape
    rows_out, cols_out = output_shape(data.shape, s)
    a = KERNELS[kernel]
    xsign, ysign = VIEWS[view]
    if cfa:
        chan_map = np.array([[CHANNELS.index(cfa.upper()[2 * r + c]) for c in (0, 1)]
                             for r in (0, 1)], np.int64)
        n_chan = 3
    else:
        chan_map = np.zeros((2, 2), np.int64)
        n_chan = 1
    basis = grid.basis()
    inv = np.linalg.inv(basis.T)
    cx_tab, cy_tab, imin, jmin = centre_table(grid)

    # Y = s * (y + (g - 1) * dy): a band of input rows lands within s * |g - 1| * max|dy|
    # of its own rows scaled by s; max|dy| is the Voronoi circumradius plus how far refined
    # centres stray from the lattice.
    stray = 0.0
    if np.isfinite(cx_tab).any():
        ii, jj = np.nonzero(np.isfinite(cx_tab))
        lattice = grid.lattice_xy(ii + imin, jj + jmin)
        stray = float(np.max(np.hypot(cx_tab[ii, jj] - lattice[:, 0],
                                      cy_tab[ii, jj] - lattice[:, 1])))
    reach = grid.pitch_px * _CELL_RADIUS[grid.lattice] + 2 * stray + 1.0
    if radius is not None:
        reach = min(reach, radius + stray + 1.0)
    g_tab, g_imin, g_jmin = lens_g if lens_g is not None else (np.full((1, 1), np.nan), 0, 0)
    g_tab = np.ascontiguousarray(g_tab, float)
    own = g_tab[np.isfinite(g_tab)]
    g_far = max(abs(g - 1.0), float(np.max(np.abs(own - 1.0))) if own.size else 0.0)
    spread = s * g_far * reach + a + 2
    n_bands = bands if bands else int(min(8, max(1, rows // 256)))
    edges = np.linspace(0, rows, n_bands + 1).round().astype(np.int64)
    lo = np.clip(np.floor(s * (edges[:-1] + 0) - spread), 0, rows_out).astype(np.int64)
    hi = np.clip(np.ceil(s * (edges[1:] - 1) + spread) + 1, 0, rows_out).astype(np.int64)
    hi = np.maximum(hi, lo)
    buf_off = np.concatenate([[0], np.cumsum(hi - lo)]).astype(np.int64)
    buf = np.zeros((int(buf_off[-1]), cols_out, 2 * n_chan))
    band_out = np.concatenate([lo, hi]).astype(np.int64)
    # a radius beyond the reach keeps every pixel, as none does (and its square stays finite)
    radius2 = -1.0 if radius is None else float(min(radius, reach)) ** 2
    _splat(data, 0.0, 0.0, inv, basis, np.asarray(grid.offset_xy, float), cx_tab, cy_tab,
           imin, jmin, float(s), float(g), xsign, ysign, mask_width / 2.0,
           radius2, chan_map, kernel_table(a), edges, band_out,
           buf_off, buf, rows_out, cols_out, g_tab, int(g_imin), int(g_jmin))
    sums = np.zeros((n_chan, rows_out, cols_out))
    weights = np.zeros((n_chan, rows_out, cols_out))
    for k in range(n_bands):  # fixed order: deterministic
        part = np.moveaxis(buf[buf_off[k]:buf_off[k + 1]], -1, 0)
        sums[:, lo[k]:hi[k]] += part[0::2]
        weights[:, lo[k]:hi[k]] += part[1::2]
    return sums, weights


def refocus(frame: np.ndarray, grid: LensGrid, *, s: float = 0.2, g: float = 4.0,
            view: str = "full", mask_width: float = 2.0, kernel: str = "lanczos3",
            radius: float | None = None, cfa: str | None = None,
            min_weight: float = 0.25, lens_g: tuple[np.ndarray, int, int] | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Refocus a focused-plenoptic sensor image (paper Eq. 3).

    Parameters
    ----------
    frame : ndarray, (rows, cols)
        Sensor image (any real dtype; NaN pixels are skipped), in the pixel coordinates of
        ``grid`` (pixel (r, c) is at (x, y) = (c, r)).
    grid : LensGrid
        Micro-lens centres.
    s : float
        Size of the refocused image relative to the sensor image (paper: 0.2).
    g : float
        Refocus parameter of Eq. 3 (paper: 4); each micro-image is magnified g times.
    view : str
        Pupil mask: full, left, right, top, bottom, q00, q01, q10, q11 (module docstring).
    mask_width : float
        m in pixels: the band |dx| <= m/2 (|dy| for top/bottom) left out of half views.
    kernel : str
        lanczos2, lanczos3, lanczos4 or bilinear.
    radius : float or None
        Keep only pixels within this distance (px) of their micro-image centre.
    cfa : str or None
        Bayer pattern at pixel (0, 0) (e.g. "RGGB"): one channel per colour, no demosaicing.
    min_weight : float
        Output pixels whose weight is below ``min_weight`` times the typical weight (the median
        of the positive weights of that channel) are NaN instead of noisy ratios.
    lens_g : (table, imin, jmin) or None
        Each lens's own g (all-in-focus, :func:`plenocli.depth.lenslet.lens_g_table`);
        ``g`` for lenses whose entry is NaN or missing.

    Returns
    -------
    image : ndarray, float32, (rows_out, cols_out) or (3, rows_out, cols_out) with ``cfa``
        Sum / weight; NaN where uncovered. Shape from :func:`output_shape`.
    weight : ndarray, float32, same shape
        The weight map (number of samples per output pixel, kernel-weighted).
    """
    _check(np.asarray(frame), grid, s, g, view, mask_width, kernel, radius, cfa, min_weight)
    sums, weights = splat_sums(frame, grid, s=s, g=g, view=view, mask_width=mask_width,
                               kernel=kernel, radius=radius, cfa=cfa, lens_g=lens_g)
    image = np.full(sums.shape, np.nan, np.float32)
    for ch in range(sums.shape[0]):
        w = weights[ch]
        positive = w[w > 0]
        typical = float(np.median(positive)) if positive.size else 0.0
        good = (w > 0) & (w >= min_weight * typical)
        image[ch][good] = (sums[ch][good] / w[good]).astype(np.float32)
    weights = weights.astype(np.float32)
    if cfa is None:
        return image[0], weights[0]
    return image, weights


def unjudged(g: float, pitch_px: float, *, mosaic: bool = False) -> str | None:
    """Why :func:`sharpness` cannot judge the focus of a plane refocused at ``g`` from
    micro-images of ``pitch_px``, or None. A channel sampled every ``step`` sensor pixels (1;
    2 for a Bayer ``mosaic``'s colours) is magnified to samples s |g| step apart: from
    |g| >= pitch / step on they are at least the lens period s * pitch apart, which the score
    smooths away, so nothing of the plane is left at its scale, only the moire of unrelated
    micro-images' samples, which scores high (raytrix-scene, g_true 4: 0.032 there, 0.53 at
    g = 44; the rise starts near that bound for pitches of 10 to 30 px, Bayer too, while true
    planes up to 0.9 of it peak where they lie)."""
    step = 2 if mosaic else 1
    if abs(g) * step >= pitch_px:
        return (f"|g| >= the lens pitch {pitch_px:.3g} px" if step == 1 else
                f"|g| >= {pitch_px / step:.3g}, the lens pitch over the {step} px step of a "
                "CFA colour")
    return None


def sharpness(image: np.ndarray, *, lens_period_px: float | None = None) -> float:
    """Focus score of a refocused image: normalised Laplacian energy below the lens frequency.

    ``image`` is (rows, cols) or (channels, rows, cols) (channels are averaged); NaN marks
    uncovered pixels. The micro-lens grid leaves a pattern of period s * pitch in every refocused
    image whatever g (micro-image centres land at s * c_ij), strongest at wrong g; a plain
    Laplacian would reward it. So the image is first smoothed with a Gaussian of
    sigma = ``lens_period_px`` / 2 (NaN-aware; it removes that period to < 1 %), then::

        score = mean(Lap(I_s)^2) / var(I_s)

    over covered pixels (5-point Laplacian, only where all five are covered). Dividing by the
    variance makes the score independent of brightness and contrast, so scores of one focal
    sweep compare planes by their share of fine (but lens-resolved) detail: the sharpest plane
    has the highest score, among planes it can judge (:func:`unjudged`). Returns NaN when
    fewer than 16 pixels are usable.
    """
    from scipy import ndimage

    img = np.asarray(image, float)
    if img.ndim not in (2, 3):
        raise ValueError(f"image must be 2-D or 3-D, got shape {img.shape}")
    planes = img.reshape(-1, *img.shape[-2:])
    if lens_period_px is not None:
        if not (np.isfinite(lens_period_px) and lens_period_px > 0):
            raise ValueError(f"lens_period_px must be positive, got {lens_period_px}")
        # each channel smoothed over its own covered pixels, kept where it has half its usual
        # cover: a Bayer plane's R and B can be holed on alternate rows and columns (g = 5 at
        # pitch 20.2: 49 % covered), which left their mean all NaN and the plane unscored
        sigma = lens_period_px / 2.0
        covered = np.isfinite(planes)
        num = ndimage.gaussian_filter(np.where(covered, planes, 0.0), (0, sigma, sigma))
        den = ndimage.gaussian_filter(covered.astype(float), (0, sigma, sigma))
        typical = np.array([np.median(d[c]) if c.any() else 1.0
                            for d, c in zip(den, covered, strict=True)])
        planes = np.where(den > 0.5 * typical[:, None, None], num / np.maximum(den, 1e-12),
                          np.nan)
        planes[:, ~covered.any(axis=0)] = np.nan
    img = planes.mean(axis=0)
    c = img[1:-1, 1:-1]
    lap = img[:-2, 1:-1] + img[2:, 1:-1] + img[1:-1, :-2] + img[1:-1, 2:] - 4.0 * c
    ok = np.isfinite(lap)
    if ok.sum() < 16:
        return float("nan")
    var = float(np.var(c[ok]))
    if var <= 0:
        return 0.0
    return float(np.mean(lap[ok] ** 2) / var)
