"""Per-lens centres: each micro-image's point-symmetry centre (every micro-image, white or
scene, Keplerian or Galilean, is point-symmetric about its centre on average: its vignetting
and its border are), and the independent checks built on the same property."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numba
import numpy as np

from plenocli.model.lensgrid import LensGrid

EDGE_MARGIN = 0.25   # border (pitches, beyond the disc) where lenses keep the lattice


# reassociation lets the sums over a disc's pixels vectorise (a quarter faster; the centres
# move by 1e-14 px); no flag that assumes finite values
@numba.njit(parallel=True, cache=True, fastmath={"reassoc", "contract", "arcp", "nsz"})
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
                half = np.sqrt(max(r2 - dy * dy, 0.0))   # the disc's chord on this row
                for c in range(max(c_lo, int(np.ceil(x - half))),
                               min(c_hi, int(np.floor(x + half))) + 1):
                    dx = c - x
                    d2 = dx * dx + dy * dy
                    t = max(1.0 - d2 / r2, 0.0)   # 0 on the rim: branch-free
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


@numba.njit(parallel=True, cache=True)
def _asymmetries(values, cx, cy, radius, inner):  # pragma: no cover - compiled
    """sum w (I(x_k) - I(2c - x_k))^2 over the pixels within ``inner`` x ``radius`` of each
    centre c / (2 sum w (I(x_k) - mean)^2) over the disc of ``radius`` (w and I(2c - x_k) as
    in _symmetry_centres), and that denominator; NaN where the disc or its mirror leaves the
    image."""
    rows, cols = values.shape
    out = np.full(cx.shape[0], np.nan)
    spreads = np.full(cx.shape[0], np.nan)
    r2 = radius * radius
    for k in numba.prange(cx.shape[0]):
        x, y = cx[k], cy[k]
        r_lo, r_hi = int(np.ceil(y - radius)), int(np.floor(y + radius))
        c_lo, c_hi = int(np.ceil(x - radius)), int(np.floor(x + radius))
        if (r_lo < 1 or c_lo < 1 or r_hi > rows - 2 or c_hi > cols - 2
                or 2 * y - r_hi < 0 or 2 * x - c_hi < 0
                or 2 * y - r_lo > rows - 2 or 2 * x - c_lo > cols - 2):
            continue
        fx2, fy2 = np.floor(2 * x), np.floor(2 * y)
        fx, fy = 2 * x - fx2, 2 * y - fy2
        ix2, iy2 = int(fx2), int(fy2)
        sw = swv = swvv = swe = 0.0
        for r in range(r_lo, r_hi + 1):
            dy = r - y
            j0 = iy2 - r
            for c in range(c_lo, c_hi + 1):
                dx = c - x
                t = max(1.0 - (dx * dx + dy * dy) / r2, 0.0)
                w = t * t
                i0 = ix2 - c
                top = values[j0, i0] + fx * (values[j0, i0 + 1] - values[j0, i0])
                bot = values[j0 + 1, i0] + fx * (values[j0 + 1, i0 + 1] - values[j0 + 1, i0])
                e = values[r, c] - (top + fy * (bot - top))
                v = values[r, c]
                sw += w
                swv += w * v
                swvv += w * v * v
                if dx * dx + dy * dy <= inner * inner * r2:
                    swe += w * e * e
        spread = swvv - swv * swv / sw if sw > 0 else 0.0
        spreads[k] = 2 * spread
        if spread > 0:
            out[k] = swe / (2 * spread)
    return out, spreads


def asymmetries(flat: np.ndarray, centres: np.ndarray, radius: float, *,
                inner: float = 1.0) -> np.ndarray:
    """(K,) how far each micro-image is from point symmetry about its centre (K, 2): the
    squared differences from its mirror image within ``inner`` x ``radius`` over twice its
    variance within ``radius`` (the rim, which carries most of a white's variance, sets the
    scale, and the inside, where a scene's content lies, is compared): 0 round, about 1
    uncorrelated with its mirror image; NaN at the border."""
    return asymmetry_parts(flat, centres, radius, inner=inner)[0]


def asymmetry_parts(flat: np.ndarray, centres: np.ndarray, radius: float, *,
                    inner: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """:func:`asymmetries` and each one's denominator (twice the micro-image's variance
    within ``radius``, weighted): their product is the squared difference itself."""
    return _asymmetries(np.ascontiguousarray(flat, np.float32),
                        np.ascontiguousarray(centres[:, 0], np.float64),
                        np.ascontiguousarray(centres[:, 1], np.float64), float(radius),
                        float(inner))


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


FOLD_BINS = 24      # bins of the folded lattice cell per lattice direction; a multiple of 6 so
#                     the holes (1/3, 1/3) and edge midpoints (1/2, 0) of the cell fall on bins
RIVAL_RATIO = 3.0   # the lens centre must be this many times rounder than any other point


@dataclass(frozen=True)
class LensCentre:
    """Which of the lattice's symmetry points are the lens centres, and how sure that is.

    ``asymmetry`` is the mean squared difference between the frame's mean micro-image and
    itself turned by one lattice step (60 deg hex, 90 deg square) about the chosen point,
    relative to twice its variance (0: round about it, 1: uncorrelated); ``rival_asymmetry``
    is the same about the best other symmetry point (a hole or an edge midpoint)."""

    offset_xy: tuple[float, float]
    asymmetry: float
    rival_asymmetry: float

    @property
    def sure(self) -> bool:
        return self.rival_asymmetry >= RIVAL_RATIO * self.asymmetry

    def to_dict(self) -> dict:
        return {"asymmetry": float(self.asymmetry),
                "rival_asymmetry": float(self.rival_asymmetry)}


def lens_centre(flat: np.ndarray, grid: LensGrid) -> LensCentre:
    """The lens centres among the symmetry points of a lattice of known pitch and angle.

    Every pixel is folded into one lattice cell (by its fractional lattice coordinates): the
    mean micro-image of the frame, scene content averaged out. A micro-image is round about
    its lens centre (round aperture, round vignetting, a round or hexagonal lens border),
    Keplerian or Galilean, bright or dark in the middle, with or without gaps: the mean
    micro-image keeps the full turn symmetry of the lattice (6-fold hex, 4-fold square) only
    about the lens centres. The holes (triangle centres of a hex lattice) are only 3-fold,
    edge midpoints 2-fold, though both are point-symmetric and, on some frames, brighter. A
    square lattice's cell centre is 4-fold too: of the two, the one about which the mean
    micro-image is round (unchanged by a 45 deg turn within 0.4 pitch) is the lens centre,
    where four micro-images meet it is not. The centre is refined between bins by a quadratic
    through the asymmetry around its minimum: the offset of a lattice whose pitch and angle
    are known, from every pixel.
    """
    n = FOLD_BINS
    cell = _folded_cell(flat, grid, bins=n)
    turned = _turn_asymmetry(cell, grid.lattice)
    a0, b0 = np.unravel_index(int(np.nanargmin(turned)), turned.shape)
    if grid.lattice == "hex":
        rivals = [(n // 3, n // 3), (2 * n // 3, 2 * n // 3), (n // 2, 0), (0, n // 2),
                  (n // 2, n // 2)]
    else:
        rivals = [(n // 2, 0), (0, n // 2)]
    asymmetry = float(turned[a0, b0])
    rival = min(float(turned[(a0 + da) % n, (b0 + db) % n]) for da, db in rivals)
    if grid.lattice == "square":   # the cell centre is 4-fold too: the rounder of the two
        across = ((a0 + n // 2) % n, (b0 + n // 2) % n)
        here, there = (_roundness(cell, *at) for at in ((a0, b0), across))
        if there < here:
            (a0, b0), here, there = across, there, here
        asymmetry, rival = max(asymmetry, here), min(rival, there)
    fa, fb = _quadratic_minimum(turned, a0, b0)
    b1, b2 = grid.basis()
    xy = np.asarray(grid.offset_xy) + (a0 + 0.5 + fa) / n * b1 + (b0 + 0.5 + fb) / n * b2
    return LensCentre((float(xy[0]), float(xy[1])), asymmetry, rival)


def _roundness(cell: np.ndarray, a0: int, b0: int, *, radius: float = 0.4) -> float:
    """Asymmetry of a square lattice's folded cell under a 45 deg turn about bin (a0, b0),
    within ``radius`` pitches (bilinear, periodic): about 0 inside a round micro-image, large
    about the cell centre where four micro-images meet (only 4-fold)."""
    n = cell.shape[0]
    r, t = np.meshgrid(np.linspace(0, radius, 12)[1:], np.linspace(0, 2 * np.pi, 48,
                                                                    endpoint=False))
    du, dv = r * np.cos(t), r * np.sin(t)
    turn = np.pi / 4
    pu, pv = (a0 + 0.5) / n, (b0 + 0.5) / n
    here = _periodic_sample(cell, pu + du, pv + dv)
    turned = _periodic_sample(cell, pu + du * np.cos(turn) - dv * np.sin(turn),
                              pv + du * np.sin(turn) + dv * np.cos(turn))
    spread = 2 * float(np.nanvar(cell))
    return float(np.nanmean((here - turned) ** 2)) / spread if spread > 0 else 1.0


def _periodic_sample(cell: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear value of the periodic folded cell at fractional lattice coordinates."""
    n = cell.shape[0]
    x, y = u * n - 0.5, v * n - 0.5   # bin k holds the centre (k + 0.5) / n
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    i0, j0 = x0.astype(np.int64) % n, y0.astype(np.int64) % n
    i1, j1 = (i0 + 1) % n, (j0 + 1) % n
    return (cell[i0, j0] * (1 - fx) * (1 - fy) + cell[i1, j0] * fx * (1 - fy)
            + cell[i0, j1] * (1 - fx) * fy + cell[i1, j1] * fx * fy)


def regional_shifts(flat: np.ndarray, grid: LensGrid, *, tiles: int = 4
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Where the lens centres of each of ``tiles`` x ``tiles`` regions sit relative to
    ``grid`` (px): the 6-fold centre of each region's own mean micro-image (see
    :func:`lens_centre`), scene content averaged over the region's lenses. Regions whose mean
    micro-image is not clearly round about one point, or whose centre is more than a quarter
    pitch from the lattice, are left out. Returns (region middles (T, 2), shifts (T, 2))."""
    rows, cols = flat.shape
    middles, shifts = [], []
    for r in range(tiles):
        for c in range(tiles):
            r0, r1 = rows * r // tiles, rows * (r + 1) // tiles
            c0, c1 = cols * c // tiles, cols * (c + 1) // tiles
            local = LensGrid(grid.pitch_px, grid.angle_rad,
                             (grid.offset_xy[0] - c0, grid.offset_xy[1] - r0), grid.lattice)
            found = lens_centre(flat[r0:r1, c0:c1], local)
            x, y = found.offset_xy[0] + c0, found.offset_xy[1] + r0
            shift = np.array([x, y]) - grid.lattice_xy(*grid.nearest_index(x, y))
            if found.sure and np.hypot(*shift) <= 0.25 * grid.pitch_px:
                middles.append(((c0 + c1 - 1) / 2, (r0 + r1 - 1) / 2))
                shifts.append(shift)
    return np.array(middles, float).reshape(-1, 2), np.array(shifts, float).reshape(-1, 2)


def _quadratic_minimum(values: np.ndarray, a0: int, b0: int) -> tuple[float, float]:
    """Sub-bin position (within +-1 bin) of the minimum of a periodic 2-D array at (a0, b0),
    from a quadratic through its 3 x 3 neighbourhood."""
    n = values.shape[0]
    da, db = (d.ravel() for d in np.meshgrid([-1, 0, 1], [-1, 0, 1], indexing="ij"))
    z = values[(a0 + da) % n, (b0 + db) % n]
    design = np.stack([np.ones(9), da, db, da * da, da * db, db * db], axis=1)
    c = np.linalg.lstsq(design, z, rcond=None)[0]
    hessian = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    if not (np.all(np.isfinite(hessian)) and np.linalg.det(hessian) > 0 and hessian[0, 0] > 0):
        return 0.0, 0.0
    step = np.clip(-np.linalg.solve(hessian, c[1:3]), -1.0, 1.0)
    return float(step[0]), float(step[1])


def _folded_cell(flat: np.ndarray, grid: LensGrid, *, bins: int) -> np.ndarray:
    """(bins, bins) mean of the image by fractional lattice coordinates (u along b1, v along
    b2, from the grid's offset); NaN where no pixel fell."""
    from scipy import ndimage

    inv = np.linalg.inv(grid.basis().T)
    total, count = _fold(np.ascontiguousarray(flat, np.float32), inv,
                         float(grid.offset_xy[0]), float(grid.offset_xy[1]), bins)
    total, count = total.reshape(bins, bins), count.reshape(bins, bins)
    # a whole-pixel pitch along the pixel axes puts every lens at one sub-pixel phase: whole
    # rows of bins get no pixel (12 px per pitch, 24 bins: every other one), and the turn
    # tests compared NaN (a square white of 12 px was calibrated on its holes, 8.5 px off).
    # Empty bins take their filled neighbours' mean (periodic), as a finer sampling would
    for _ in range(bins):
        empty = count == 0
        if not empty.any() or empty.all():
            break
        near_total = ndimage.uniform_filter(total, 3, mode="wrap")
        near_count = ndimage.uniform_filter(count, 3, mode="wrap")
        fill = empty & (near_count > 0)
        total = np.where(fill, near_total / np.where(fill, near_count, 1), total)
        count = np.where(fill, 1.0, count)
    with np.errstate(invalid="ignore", divide="ignore"):
        return total / count


@numba.njit(parallel=True, cache=True)
def _fold(flat, inv, x0, y0, bins):  # pragma: no cover - compiled
    """Sums and counts of the pixels per bin of fractional lattice coordinates (``inv``: the
    inverse of the basis as columns), one accumulator per band of rows (numba kernel: no
    per-pixel temporaries)."""
    rows, cols = flat.shape
    bands = (rows + 255) // 256
    total = np.zeros((bands, bins * bins))
    count = np.zeros((bands, bins * bins))
    for band in numba.prange(bands):
        for r in range(band * 256, min(band * 256 + 256, rows)):
            y = r - y0
            for c in range(cols):
                x = c - x0
                u = int(np.floor((inv[0, 0] * x + inv[0, 1] * y) * bins)) % bins
                v = int(np.floor((inv[1, 0] * x + inv[1, 1] * y) * bins)) % bins
                total[band, u * bins + v] += flat[r, c]
                count[band, u * bins + v] += 1.0
    return total.sum(axis=0), count.sum(axis=0)


@functools.lru_cache(maxsize=4)
def _turned_bins(n: int, lattice: str) -> np.ndarray:
    """(n, n, n, n) flat bin of (a, b) turned about every pivot bin (a0, b0), indexed
    [a0, b0, a, b] (one table per cell size and lattice: every fold reuses it)."""
    a, b = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a0, b0 = a[:, :, None, None], b[:, :, None, None]
    da, db = a[None, None] - a0, b[None, None] - b0
    turned_a = (a0 - db) % n
    turned_b = (b0 + da + db) % n if lattice == "hex" else (b0 + da) % n
    bins = turned_a * n + turned_b
    bins.flags.writeable = False
    return bins


def _turn_asymmetry(cell: np.ndarray, lattice: str) -> np.ndarray:
    """(n, n): for every bin centre as the pivot, the mean squared difference between the
    periodic cell and the cell turned by one lattice step about it, over twice its variance.
    In lattice coordinates the turn is an integer map: hex (du, dv) -> (-dv, du + dv) (b1 ->
    b2, b2 -> b2 - b1), square (du, dv) -> (-dv, du)."""
    n = cell.shape[0]
    diff = cell.ravel()[_turned_bins(n, lattice)] - cell[None, None]
    spread = 2 * float(np.nanvar(cell))
    if not spread > 0:
        return np.ones((n, n))
    return np.nanmean(diff * diff, axis=(2, 3)) / spread

