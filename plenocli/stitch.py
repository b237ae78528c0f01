"""Extended-FOV stitching of 2 (side by side) or 4 (2 x 2) views into one panorama.

Geometry convention: a transform is a 3 x 3 matrix mapping a view's pixel ``(x, y, 1)`` (column,
row) to the pixel coordinates of view 0 (the reference). The panorama is view 0's pixel grid
extended to cover every view; ``report["origin_px"]`` is the panorama pixel ``[row, col]`` of view
0's pixel (0, 0). Views are ordered row-major over the layout: ``1x2`` = left, right; ``2x1`` =
top, bottom; ``2x2`` = S00, S01, S10, S11 (top-left, top-right, bottom-left, bottom-right).

Registration of a pair of neighbours (b to the right of / below a):
- ``translation``: integer search by masked normalised cross-correlation over the whole overlap
  (only shifts in the expected overlap direction, or near a rig's / ``overlap``'s prediction;
  ambiguous matches are refused), then sub-pixel refinement (ECC, then photometric least squares).
- With a prism ``rig`` (:mod:`plenocli.prismrig`) the views are first resampled into a common
  undistorted frame, which cancels the prisms' constant distortion.
- ``homography``: SIFT features, ratio test, matches restricted to the expected direction,
  RANSAC, then ECC refinement (homography) on the overlap.
Both work on high-passed images, so slow vignetting and gain differences do not pull the fit.
Exposure is then matched from the overlaps (per-view, per-channel gain, least squares in log
gain with view 0 fixed) and the seams are blended (feathering, or multi-band).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import cv2
import numpy as np
from scipy import ndimage

from plenocli.errors import InputError
from plenocli.prismrig import PrismRig, fill_nan, undistort_views

LAYOUTS = {"1x2": (1, 2), "2x1": (2, 1), "2x2": (2, 2)}
MODELS = ("translation", "homography")
BLENDS = ("feather", "multiband")
_HIGHPASS_SIGMA_PX = 8.0


# ---------------------------------------------------------------------------------------------
# input handling
def as_view_stack(views: np.ndarray | Sequence[np.ndarray]) -> tuple[np.ndarray, bool]:
    """Validate views and return them as (V, C, rows, cols) float32 plus ``colour`` (C given).

    ``views`` is (V, rows, cols), (V, C, rows, cols) or a sequence of equally shaped arrays.
    Views of different sizes or channel counts are rejected (crop or resample them first).
    """
    if isinstance(views, np.ndarray):
        arrays = list(views)
    else:
        arrays = [np.asarray(v) for v in views]
    if len(arrays) not in (2, 4):
        raise InputError(f"stitch needs 2 or 4 views, got {len(arrays)}; select views with "
                         "--views (e.g. --views A,B)")
    first = arrays[0].shape
    for k, a in enumerate(arrays):
        if a.ndim not in (2, 3):
            raise InputError(f"view {k} has shape {a.shape}; a view is (rows, cols) or "
                             "(channels, rows, cols)")
        if a.shape != first:
            what = "channel count" if a.ndim != len(first) or a.shape[-2:] == first[-2:] else "size"
            raise InputError(f"view {k} has shape {a.shape} but view 0 has {first} (different "
                             f"{what}); stitch needs views of one size and one channel count")
    colour = len(first) == 3
    stack = np.stack([a if colour else a[np.newaxis] for a in arrays]).astype(np.float32)
    if min(stack.shape[-2:]) < 32:
        raise InputError(f"views of {stack.shape[-2]} x {stack.shape[-1]} px are too small to "
                         "register; need at least 32 x 32")
    return stack, colour


def undistort(image: np.ndarray, k1: float) -> np.ndarray:
    """Remove a constant radial distortion ``r_d = r_u (1 + k1 r_u^2)`` from a (rows, cols) image.

    ``r`` is measured from the image centre in units of the half-diagonal, so ``k1 = 0.01`` moves
    the corners outward by 1 %. Resampled with Lanczos-4; NaN stays NaN (within the kernel).
    """
    if k1 == 0:
        return image
    rows, cols = image.shape
    cy, cx = (rows - 1) / 2, (cols - 1) / 2
    norm = np.hypot(cy, cx)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float32)
    ru2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / norm**2
    scale = 1.0 + k1 * ru2
    map_x = (cx + (xx - cx) * scale).astype(np.float32)
    map_y = (cy + (yy - cy) * scale).astype(np.float32)
    return cv2.remap(image.astype(np.float32), map_x, map_y, cv2.INTER_LANCZOS4,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)


def _highpass(image: np.ndarray) -> np.ndarray:
    """Texture only: image minus a wide Gaussian blur, float32 (removes vignetting and offsets).

    With NaN (no data) the blur is a normalised convolution over the valid pixels and the
    result is 0 where there is no data, so the edges of a view's data add no false texture.
    """
    valid = np.isfinite(image)
    if valid.all():
        img = image.astype(np.float32)
        return img - cv2.GaussianBlur(img, (0, 0), _HIGHPASS_SIGMA_PX)
    m = valid.astype(np.float32)
    img = np.where(valid, image, 0).astype(np.float32)
    blur = cv2.GaussianBlur(img, (0, 0), _HIGHPASS_SIGMA_PX) / np.maximum(
        cv2.GaussianBlur(m, (0, 0), _HIGHPASS_SIGMA_PX), 1e-6)
    return np.where(valid, img - blur, 0).astype(np.float32)


def _pairs(layout: str) -> list[tuple[int, int, str]]:
    """Neighbour pairs (a, b, direction): 'h' = b right of a, 'v' = b below a."""
    return {"1x2": [(0, 1, "h")], "2x1": [(0, 1, "v")],
            "2x2": [(0, 1, "h"), (0, 2, "v"), (1, 3, "v"), (2, 3, "h")]}[layout]


def _translation_matrix(dy: float, dx: float) -> np.ndarray:
    m = np.eye(3)
    m[0, 2], m[1, 2] = dx, dy
    return m


# ---------------------------------------------------------------------------------------------
# pairwise registration
def _ncc(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / den) if den > 0 else 0.0


def _shift_crop(n_a: int, n_b: int, t0: int, t1: int) -> tuple[slice, slice, int, int, int]:
    """Along one axis: the parts of a (length n_a) and b (n_b) that can overlap for the shifts
    t0..t1 (b(q) <-> a(q + t)), the shift range in the crops' coordinates and the circular
    correlation length that holds those shifts without wrap-around."""
    a_lo, a_hi = max(0, t0), min(n_a, n_b + t1)
    b_lo, b_hi = max(0, -t1), min(n_b, n_a - t0)
    c0, c1 = t0 + b_lo - a_lo, t1 + b_lo - a_lo
    nx, ny = a_hi - a_lo, b_hi - b_lo
    length = max(nx - c0, c1 + ny, nx, ny)
    return slice(a_lo, a_hi), slice(b_lo, b_hi), c0, c1, length


def masked_ncc_window(a: np.ndarray, b: np.ndarray, valid_a: np.ndarray, valid_b: np.ndarray,
                      *, dy_range: tuple[int, int], dx_range: tuple[int, int], min_pixels: int,
                      dtype: type = np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Masked normalised cross-correlation of b against a for the shifts in the given
    inclusive ranges only (Padfield's masked NCC by FFT).

    Entry ``[dy - dy_range[0], dx - dx_range[0]]`` is the NCC over the pixels q valid in both
    with b(q) <-> a(q + (dy, dx)). Only the strips of a and b that can overlap for these shifts
    are transformed, with the shortest circular correlation that does not wrap, and the six
    forward real FFTs are shared by the six correlations (12 transforms). ``dtype`` float32
    halves time and memory (the NCC stays within ~1e-5). Shifts overlapping fewer than
    ``min_pixels`` pixels (or outside the views) get -1. Returns the NCC and the overlap
    pixel counts, both (dy_range[1] - dy_range[0] + 1, dx_range[1] - dx_range[0] + 1).
    """
    from scipy import fft

    (rows_a, cols_a), (rows_b, cols_b) = a.shape, b.shape
    out_shape = (dy_range[1] - dy_range[0] + 1, dx_range[1] - dx_range[0] + 1)
    ncc_out = np.full(out_shape, -1.0)
    n_out = np.zeros(out_shape)
    # shifts with any overlap at all
    ty0, ty1 = max(dy_range[0], -(rows_b - 1)), min(dy_range[1], rows_a - 1)
    tx0, tx1 = max(dx_range[0], -(cols_b - 1)), min(dx_range[1], cols_a - 1)
    if ty1 < ty0 or tx1 < tx0:
        return ncc_out, n_out
    ay, by, cy0, cy1, len_y = _shift_crop(rows_a, rows_b, ty0, ty1)
    ax, bx, cx0, cx1, len_x = _shift_crop(cols_a, cols_b, tx0, tx1)
    shape = (fft.next_fast_len(len_y, real=True), fft.next_fast_len(len_x, real=True))
    ma, mb = valid_a[ay, ax].astype(dtype), valid_b[by, bx].astype(dtype)
    fa = np.where(valid_a[ay, ax], a[ay, ax], 0).astype(dtype)
    fb = np.where(valid_b[by, bx], b[by, bx], 0).astype(dtype)

    def spectrum(x):
        return fft.rfft2(x, s=shape, workers=-1)

    spec_ma, spec_fa, spec_faa = spectrum(ma), spectrum(fa), spectrum(fa * fa)
    del ma
    spec_mb, spec_fb, spec_fbb = (np.conj(spectrum(x)) for x in (mb, fb, fb * fb))
    del mb, fa, fb
    rows = np.arange(cy0, cy1 + 1) % shape[0]
    cols = np.arange(cx0, cx1 + 1) % shape[1]

    def corr(x, y):  # sum_q x(q + t) y(q) for the wanted t, float64
        return fft.irfft2(x * y, s=shape, workers=-1)[np.ix_(rows, cols)].astype(np.float64)

    n = np.rint(corr(spec_ma, spec_mb))
    sa, sb = corr(spec_fa, spec_mb), corr(spec_ma, spec_fb)
    saa, sbb, sab = corr(spec_faa, spec_mb), corr(spec_ma, spec_fbb), corr(spec_fa, spec_fb)
    n_safe = np.maximum(n, 1)
    num = sab - sa * sb / n_safe
    var = np.maximum(saa - sa * sa / n_safe, 0) * np.maximum(sbb - sb * sb / n_safe, 0)
    # float32 transforms leave rounding noise ~1e-7 of the largest terms in empty overlaps
    floor = (1e-12 if np.dtype(dtype) == np.float64 else 1e-8) * max(float(var.max()), 1e-30)
    ok = (n >= min_pixels) & (var > floor)
    ncc = np.where(ok, num / np.sqrt(np.where(ok, var, 1.0)), -1.0)
    sy = slice(ty0 - dy_range[0], ty1 - dy_range[0] + 1)
    sx = slice(tx0 - dx_range[0], tx1 - dx_range[0] + 1)
    ncc_out[sy, sx] = np.clip(ncc, -1.0, 1.0)
    n_out[sy, sx] = n
    return ncc_out, n_out


def masked_ncc_surface(a: np.ndarray, b: np.ndarray, valid_a: np.ndarray, valid_b: np.ndarray,
                       *, min_pixels: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation of b against a over their common valid pixels, every shift.

    Entry ``[dy + rows_b - 1, dx + cols_b - 1]`` is the NCC over the pixels q valid in both with
    b(q) <-> a(q + (dy, dx)) (see :func:`masked_ncc_window`, which computes only a range of
    shifts). Returns the surface and the overlap pixel counts; shifts overlapping fewer than
    ``min_pixels`` pixels get -1.
    """
    return masked_ncc_window(a, b, valid_a, valid_b, dy_range=(1 - b.shape[0], a.shape[0] - 1),
                             dx_range=(1 - b.shape[1], a.shape[1] - 1), min_pixels=min_pixels)


def _valid_eroded(view: np.ndarray) -> np.ndarray:
    """Pixels with data, eroded by 2 px (the view's border counts as no data)."""
    finite = np.isfinite(view)
    if not finite.all():
        return ndimage.binary_erosion(finite, iterations=2)
    finite[:2], finite[-2:], finite[:, :2], finite[:, -2:] = False, False, False, False
    return finite


def _coarse_factor(shape: tuple[int, int], dy_range: tuple[int, int],
                   dx_range: tuple[int, int]) -> int:
    """Downsampling for the coarse search: 4 or 2 while the views keep >= 256 px on their
    short side and the range spans more than a fine window; 1 = search at full resolution."""
    span = max(dy_range[1] - dy_range[0], dx_range[1] - dx_range[0])
    for factor in (4, 2):
        if min(shape) >= 256 * factor and span > 8 * factor:
            return factor
    return 1


def _downsample(image: np.ndarray, valid: np.ndarray, factor: int):
    """Area mean by ``factor`` and the coarse pixels whose every fine pixel is valid."""
    rows, cols = (s // factor * factor for s in image.shape)
    size = (cols // factor, rows // factor)
    img = cv2.resize(np.where(valid, image, 0)[:rows, :cols].astype(np.float32), size,
                     interpolation=cv2.INTER_AREA)
    mask = cv2.resize(valid[:rows, :cols].astype(np.float32), size,
                      interpolation=cv2.INTER_AREA) > 0.999
    return img, mask


def _peaks(surface: np.ndarray, exclusion: float, count: int) -> list[tuple[int, int]]:
    """Positions of the ``count`` highest values of a surface, each further than
    ``exclusion`` from the higher ones (greedy)."""
    work = surface.copy()
    yy, xx = np.ogrid[0:work.shape[0], 0:work.shape[1]]
    found = []
    for _ in range(count):
        py, px = np.unravel_index(int(np.argmax(work)), work.shape)
        if work[py, px] <= -1:
            break
        found.append((int(py), int(px)))
        work[np.hypot(yy - py, xx - px) <= exclusion] = -np.inf
    return found


def _search_highpassed(ha: np.ndarray, hb: np.ndarray, va: np.ndarray, vb: np.ndarray, *,
                       dy_range: tuple[int, int], dx_range: tuple[int, int], min_pixels: int,
                       exclusion_px: int) -> tuple[int, int, float, float]:
    """:func:`search_shift` on high-passed views with their valid masks (coarse to fine)."""
    factor = _coarse_factor(ha.shape, dy_range, dx_range)
    if factor == 1:
        window, _ = masked_ncc_window(ha, hb, va, vb, dy_range=dy_range, dx_range=dx_range,
                                      min_pixels=min_pixels)
        py, px = np.unravel_index(int(np.argmax(window)), window.shape)
        best = float(window[py, px])
        yy, xx = np.ogrid[0:window.shape[0], 0:window.shape[1]]
        far = np.hypot(yy - py, xx - px) > exclusion_px
        second = float(window[far].max()) if far.any() else -1.0
        return int(py) + dy_range[0], int(px) + dx_range[0], best, second
    # coarse: the whole range on views downsampled by `factor`, float32; its best peaks
    # (the match and the runner-ups) are then scored again at full resolution in small windows
    ca, cva = _downsample(ha, va, factor)
    cb, cvb = _downsample(hb, vb, factor)
    cy_range = (-(-dy_range[0] // factor), dy_range[1] // factor)
    cx_range = (-(-dx_range[0] // factor), dx_range[1] // factor)
    coarse, _ = masked_ncc_window(ca, cb, cva, cvb, dy_range=cy_range, dx_range=cx_range,
                                  min_pixels=max(1, min_pixels // factor**2), dtype=np.float32)
    peaks = _peaks(coarse, max(exclusion_px / factor, 1.5), 3)
    half = 2 * factor
    scored: dict[tuple[int, int], float] = {}
    for py, px in peaks:
        centre = ((py + cy_range[0]) * factor, (px + cx_range[0]) * factor)
        for _ in range(4):  # follow the peak if it lies on the window's edge
            wy = (max(dy_range[0], centre[0] - half), min(dy_range[1], centre[0] + half))
            wx = (max(dx_range[0], centre[1] - half), min(dx_range[1], centre[1] + half))
            fine, _ = masked_ncc_window(ha, hb, va, vb, dy_range=wy, dx_range=wx,
                                        min_pixels=min_pixels, dtype=np.float32)
            for (iy, ix), value in np.ndenumerate(fine):
                scored[(iy + wy[0], ix + wx[0])] = float(value)
            iy, ix = np.unravel_index(int(np.argmax(fine)), fine.shape)
            top = (int(iy) + wy[0], int(ix) + wx[0])
            on_edge = ((top[0] in wy and top[0] not in dy_range)
                       or (top[1] in wx and top[1] not in dx_range))
            if not on_edge or top == centre:
                break
            centre = top
    shifts = np.array(list(scored.keys()))
    values = np.array(list(scored.values()))
    k = int(np.argmax(values))
    far = np.hypot(*(shifts - shifts[k]).T) > exclusion_px
    second = float(values[far].max()) if far.any() else -1.0
    return int(shifts[k, 0]), int(shifts[k, 1]), float(values[k]), second


def search_shift(a: np.ndarray, b: np.ndarray, *, dy_range: tuple[int, int],
                 dx_range: tuple[int, int], min_pixels: int, exclusion_px: int = 6
                 ) -> tuple[int, int, float, float]:
    """Integer shift (dy, dx) maximising the masked NCC of high-passed b against a over the
    whole overlap, within the given inclusive ranges; also the best score elsewhere (the
    runner-up outside ``exclusion_px`` of the best), which tells whether the match is unique.

    Whole-overlap NCC (not a thin edge strip) makes a periodic scene's false matches, shifted by
    a multiple of the period, score clearly lower: over the whole overlap they disagree
    somewhere (different cell contents, the overlap's other end).

    Large views with a wide range are searched coarse to fine: the whole range on views
    downsampled 2x or 4x (short side >= 256 px), then the three best coarse peaks (each
    further than ``exclusion_px`` from the others) are scored at full resolution within
    +-2 x the factor px; the match and the runner-up are the best of those full-resolution
    scores. Small views or narrow ranges are searched at full resolution directly.
    """
    rows_b, cols_b = b.shape
    dy_range = (max(dy_range[0], 1 - rows_b), min(dy_range[1], a.shape[0] - 1))
    dx_range = (max(dx_range[0], 1 - cols_b), min(dx_range[1], a.shape[1] - 1))
    if dy_range[1] < dy_range[0] or dx_range[1] < dx_range[0]:
        raise InputError("the expected overlap lies outside the views; check --layout and "
                         "--overlap")
    return _search_highpassed(_highpass(a), _highpass(b), _valid_eroded(a), _valid_eroded(b),
                              dy_range=dy_range, dx_range=dx_range, min_pixels=min_pixels,
                              exclusion_px=exclusion_px)


def _overlap_crops(a: np.ndarray, b: np.ndarray, dy: int, dx: int):
    """Same-size crops of a and b over their overlap for b(q) <-> a(q + (dy, dx)), or None."""
    rows, cols = a.shape
    y0, y1 = max(0, dy), min(rows, rows + dy)
    x0, x1 = max(0, dx), min(cols, cols + dx)
    if y1 - y0 < 8 or x1 - x0 < 8:
        return None
    return a[y0:y1, x0:x1], b[y0 - dy:y1 - dy, x0 - dx:x1 - dx], (y0, x0)


def estimate_translation(a: np.ndarray, b: np.ndarray, *, direction: str = "h",
                         max_overlap: float = 0.7, min_overlap_px: int = 16,
                         max_cross_px: int | None = None,
                         min_correlation: float = 0.4,
                         prior: tuple[float, float] | None = None,
                         tolerance_px: float | None = None,
                         max_ambiguity: float = 0.9) -> tuple[float, float, dict]:
    """Sub-pixel shift of view b against view a: b's pixel (y, x) shows a's (y + dy, x + dx).

    Parameters
    ----------
    a, b : (rows, cols) views (NaN allowed); b lies to the right of a (``direction="h"``) or
        below it (``"v"``).
    max_overlap : largest overlap searched, fraction of the view width (height for "v").
    min_overlap_px : width of b's edge strip used for the search (the overlap must be at least
        this wide).
    max_cross_px : largest shift across the stitching direction searched (default 10 % of the
        view's other side).
    min_correlation : below this normalised cross-correlation over the overlap the views are
        declared not to overlap (``InputError``).
    prior : expected shift (dy, dx) px, e.g. from a rig model or an expected overlap; the
        search is then restricted to ``tolerance_px`` (default 5 % of the view, >= 8 px)
        around it instead of the whole range above.
    max_ambiguity : the best whole-overlap correlation elsewhere (outside 6 px of the match)
        must stay below this fraction of the match's, else the match is ambiguous (a periodic
        scene, or too little overlap) and ``InputError`` is raised instead of a ghosted result.

    Returns
    -------
    dy, dx : shift in px. info : dict with ``correlation``, ``overlap_px``, ``overlap_fraction``,
    ``runner_up_correlation``.
    """
    if direction not in ("h", "v"):
        raise ValueError(f"direction must be 'h' or 'v', got {direction!r}")
    if not 0 < max_overlap <= 1:
        raise ValueError(f"max_overlap must be in (0, 1], got {max_overlap}")
    if direction == "v":
        dx, dy, info = estimate_translation(
            a.T, b.T, direction="h", max_overlap=max_overlap, min_overlap_px=min_overlap_px,
            max_cross_px=max_cross_px, min_correlation=min_correlation,
            prior=None if prior is None else (prior[1], prior[0]), tolerance_px=tolerance_px,
            max_ambiguity=max_ambiguity)
        return dy, dx, info
    ha, hb = _highpass(a), _highpass(b)
    for name, h in (("a", ha), ("b", hb)):
        if float(h.std()) <= 1e-6 * max(float(np.nanmax(np.abs(a))), 1e-12):
            raise InputError(f"view {name} has no texture (flat image); stitching needs "
                             "structure in the overlap")
    rows, cols = a.shape
    cross = int(max_cross_px if max_cross_px is not None else round(0.1 * rows))
    cross = min(cross, rows // 4)
    strip = max(int(min_overlap_px), 8)
    x_start = max(0, int(np.floor(cols * (1 - max_overlap))))
    if cols - x_start < strip:
        raise ValueError(f"max_overlap {max_overlap} leaves less than {strip} px to search")
    if prior is not None:
        tol = int(np.ceil(tolerance_px if tolerance_px is not None
                          else max(8.0, 0.05 * max(rows, cols))))
        dy_range = (int(np.floor(prior[0])) - tol, int(np.ceil(prior[0])) + tol)
        dx_range = (int(np.floor(prior[1])) - tol, int(np.ceil(prior[1])) + tol)
    else:
        dy_range, dx_range = (-cross, cross), (x_start, cols - strip)
    min_pixels = max(64, strip * (rows - 2 * cross) // 2)
    rows_b, cols_b = b.shape
    dy_range = (max(dy_range[0], 1 - rows_b), min(dy_range[1], rows - 1))
    dx_range = (max(dx_range[0], 1 - cols_b), min(dx_range[1], cols - 1))
    if dy_range[1] < dy_range[0] or dx_range[1] < dx_range[0]:
        raise InputError("the expected overlap lies outside the views; check --layout and "
                         "--overlap")
    dy0, dx0, best, second = _search_highpassed(ha, hb, _valid_eroded(a), _valid_eroded(b),
                                                dy_range=dy_range, dx_range=dx_range,
                                                min_pixels=min_pixels, exclusion_px=6)
    if best < min_correlation:
        raise InputError(f"no reliable overlap found between the views (best normalised "
                         f"correlation {best:.2f} < {min_correlation}); the views may not "
                         "overlap, or the overlap has no texture")
    if second >= max_ambiguity * best:
        raise InputError(f"ambiguous overlap: shifts correlating {best:.2f} and {second:.2f} "
                         "(a periodic scene?); give the expected overlap (--overlap) or the "
                         "rig (--rig)")
    crops = _overlap_crops(ha, hb, dy0, dx0)
    if crops is None:
        raise InputError("no overlap found between the views; check the layout (--layout) and "
                         "that the views overlap")
    # sub-pixel refinement: ECC (translation) on the overlap of the raw views; ECC is invariant
    # to gain and offset, and the raw views resample without the bias a high-pass would add
    _, _, (y0, x0) = crops
    ra, rb = fill_nan(a).astype(np.float32), fill_nan(b).astype(np.float32)
    rows_ov, cols_ov = crops[0].shape
    has_nan = not (np.isfinite(a).all() and np.isfinite(b).all())
    ca = ra[y0:y0 + rows_ov, x0:x0 + cols_ov]
    cb = rb[y0 - dy0:y0 - dy0 + rows_ov, x0 - dx0:x0 - dx0 + cols_ov]
    warp = np.float32([[1, 0, x0 - dx0], [0, 1, y0 - dy0]])  # crop of a -> b
    method = "ecc"
    # two passes: the photometric ratio field is re-estimated once the shift is sub-pixel
    # (views with no-data regions, e.g. undistorted canvases, skip ECC: it cannot mask them).
    # ECC stops once its correlation gains less than 1e-6: the photometric fit below sets the
    # final shift (1e-8 took ten times the iterations for the same final result)
    for _ in range(0 if has_nan else 2):
        b_on_a = cv2.warpAffine(rb, warp, (cols_ov, rows_ov),
                                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_REPLICATE)
        template = _match_photometry(ca, b_on_a, np.ones(ca.shape, bool))
        try:
            _, warp = cv2.findTransformECC(template, rb, warp, cv2.MOTION_TRANSLATION,
                                           (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 200,
                                            1e-6), None, 1)
        except cv2.error:
            method = "phase-correlation"
            break
    if has_nan:
        ty = tx = 0.0
        method = "template"
    elif method == "ecc":
        ty, tx = float(warp[1, 2]) - (y0 - dy0), float(warp[0, 2]) - (x0 - dx0)
    else:
        window = cv2.createHanningWindow((ca.shape[1], ca.shape[0]), cv2.CV_64F)
        (tx, ty), _ = cv2.phaseCorrelate(cb.astype(np.float64), ca.astype(np.float64), window)
    if abs(ty) > 2 or abs(tx) > 2:  # refinement ran away: keep the integer match
        ty = tx = 0.0
        method = "template"
    dy, dx = dy0 - ty, dx0 - tx
    # final photometric least squares with spline resampling: ECC's bilinear warps leave a
    # texture-dependent bias of up to ~0.2 px on smooth, large views
    try:
        (sa, sb), (off_y, off_x) = _translation_crops(a.shape, b.shape, dy, dx)
        shifted, _ = refine_homography(a[sa], b[sb], _translation_matrix(dy - off_y, dx - off_x),
                                       motion="translation")
        ry, rx = float(shifted[1, 2]) + off_y, float(shifted[0, 2]) + off_x
        if abs(ry - dy) < 1 and abs(rx - dx) < 1:
            dy, dx = ry, rx
            method += "+photometric"
    except ValueError:
        pass
    correlation = _aligned_correlation(ha, hb, _translation_matrix(dy, dx), a, b)
    overlap_px = cols - dx
    info = {"correlation": correlation, "overlap_px": float(overlap_px),
            "overlap_fraction": float(overlap_px / cols), "refinement": method,
            "runner_up_correlation": second}
    if not np.isfinite(correlation) or correlation < min_correlation:
        raise InputError(f"no reliable overlap found between the views (best normalised "
                         f"correlation {correlation:.2f} < {min_correlation}); the views may not "
                         "overlap, or the overlap has no texture")
    return float(dy), float(dx), info


def _translation_crops(shape_a: tuple[int, int], shape_b: tuple[int, int], dy: float,
                       dx: float, margin_px: int = 16):
    """Crops of a and b (slices) holding their overlap for b(q) <-> a(q + (dy, dx)) plus a
    margin, and the offset to subtract from the shift in the crops' coordinates (crop origins
    on multiples of 4, so the refinement's pyramid samples as on the whole views)."""
    slices_a, slices_b, offset = [], [], []
    for n_a, n_b, t in zip(shape_a, shape_b, (dy, dx), strict=True):
        lo = max(0, (int(np.floor(max(t, 0.0))) - margin_px) // 4 * 4)
        hi = min(n_a, int(np.ceil(n_b + t)) + margin_px)
        lo_b = max(0, (int(np.floor(lo - t)) - margin_px) // 4 * 4)
        hi_b = min(n_b, int(np.ceil(hi - t)) + margin_px)
        slices_a.append(slice(lo, hi))
        slices_b.append(slice(lo_b, hi_b))
        offset.append(lo - lo_b)
    return (tuple(slices_a), tuple(slices_b)), tuple(offset)


def _aligned_correlation(ha: np.ndarray, hb: np.ndarray, h_ab: np.ndarray,
                         a: np.ndarray | None = None, b: np.ndarray | None = None) -> float:
    """NCC of a and b (high-passed) over their overlap once b is warped into a by ``h_ab``
    (only over the pixels with data in both when the raw views ``a``, ``b`` are given)."""
    rows, cols = ha.shape
    warped = cv2.warpPerspective(hb, h_ab, (cols, rows), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    valid_b = np.ones_like(hb) if b is None else np.isfinite(b).astype(np.float32)
    cover = cv2.warpPerspective(valid_b, h_ab, (cols, rows), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0) > 0.999
    if a is not None:
        cover &= np.isfinite(a)
    cover = ndimage.binary_erosion(cover, iterations=2)
    if cover.sum() < 64:
        return float("nan")
    return _ncc(ha[cover], warped[cover])


def _match_photometry(template: np.ndarray, other: np.ndarray, mask: np.ndarray,
                      sigma_px: float = 8.0) -> np.ndarray:
    """``template`` times the smooth ratio field blur(other) / blur(template) over ``mask``.

    ``other`` is the second view already resampled onto ``template`` (roughly aligned). Both
    blurs see the same scene content, so their ratio is the relative vignetting and gain
    between the views; removing it keeps ECC from being pulled by fall-offs that differ
    between the views (each view is darker towards its own edge).
    """
    m = mask.astype(np.float32)
    t = np.where(mask, template, 0).astype(np.float32)
    o = np.where(mask, other, 0).astype(np.float32)
    blur_m = cv2.GaussianBlur(m, (0, 0), sigma_px)
    blur_t = cv2.GaussianBlur(t, (0, 0), sigma_px) / np.maximum(blur_m, 1e-6)
    blur_o = cv2.GaussianBlur(o, (0, 0), sigma_px) / np.maximum(blur_m, 1e-6)
    scale = float(np.abs(blur_t[mask]).max()) if mask.any() else 0.0
    if scale == 0 or float(blur_t[mask].min()) <= 0.05 * scale:
        return template.astype(np.float32)  # signed or dark data: leave as is
    ratio = np.where(mask, blur_o / np.maximum(blur_t, 1e-6 * scale), 1.0)
    return (template * ratio).astype(np.float32)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    img = fill_nan(image)
    lo, hi = np.percentile(img, [0.5, 99.5])
    return np.clip(255 * (img - lo) / max(hi - lo, 1e-12), 0, 255).astype(np.uint8)


def _polynomial_terms(xn: np.ndarray, yn: np.ndarray, degree: int) -> np.ndarray:
    """(N, terms) monomials xn^i yn^j with i + j <= degree (coordinates in [-1, 1])."""
    return np.stack([xn**i * yn**j for i in range(degree + 1) for j in range(degree + 1 - i)],
                    axis=1)


def _refine_level(a: np.ndarray, b: np.ndarray, valid_a: np.ndarray, valid_b: np.ndarray,
                  h_ab: np.ndarray, *, max_points: int, iterations: int, degree: int,
                  tol_px: float, motion: str) -> tuple[np.ndarray, dict]:
    """One pyramid level of :func:`refine_homography` (float64 images, NaN already filled)."""
    rows, cols = a.shape
    cover = cv2.warpPerspective(valid_b.astype(np.float32), h_ab, (cols, rows),
                                flags=cv2.INTER_LINEAR) > 0.999
    cover = ndimage.binary_erosion(cover & valid_a, iterations=3)
    ys, xs = np.nonzero(cover)
    if ys.size < 256:
        raise ValueError(f"the overlap holds only {ys.size} px; too small to refine")
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    if ys.size > max_points:  # a fixed random subset (a regular subgrid biased the shift)
        keep = np.random.default_rng(0).choice(ys.size, max_points, replace=False)
        keep.sort()
        ys, xs = ys[keep], xs[keep]
    grad_y, grad_x = np.gradient(a[y0 - 1:y1 + 1, x0 - 1:x1 + 1])
    template = a[ys, xs]
    # normalised template coordinates (centre of the overlap, half its longer side) keep the
    # Gauss-Newton system well conditioned
    cx, cy, scale = (x0 + x1 - 1) / 2, (y0 + y1 - 1) / 2, max(x1 - x0, y1 - y0) / 2
    from_norm = np.array([[scale, 0.0, cx], [0.0, scale, cy], [0.0, 0.0, 1.0]])
    xn, yn = (xs - cx) / scale, (ys - cy) / scale
    gx = grad_x[ys - y0 + 1, xs - x0 + 1] * scale
    gy = grad_y[ys - y0 + 1, xs - x0 + 1] * scale
    radial = gx * xn + gy * yn
    # steepest-descent images of the inverse-compositional homography update at identity
    steepest = np.stack([gx * xn, gx * yn, gx, gy * xn, gy * yn, gy, -xn * radial,
                         -yn * radial], axis=1)
    if motion == "translation":
        steepest = steepest[:, [2, 5]]
    poly = _polynomial_terms(xn, yn, degree)
    coeffs = ndimage.spline_filter(b, order=3)
    bad_b = ndimage.binary_dilation(~valid_b, iterations=2)
    g = np.linalg.inv(h_ab) @ from_norm  # normalised template coordinates -> b pixels
    pts = np.stack([xn, yn, np.ones_like(xn)])
    step_px = np.inf
    err = np.zeros_like(template)
    use = np.ones(template.shape, bool)
    done = 0
    while done < iterations:
        done += 1
        q = g @ pts
        bx, by = q[0] / q[2], q[1] / q[2]
        inside = (bx >= 1) & (bx <= b.shape[1] - 2) & (by >= 1) & (by <= b.shape[0] - 2)
        bxi = np.clip(np.rint(bx), 0, b.shape[1] - 1).astype(int)
        byi = np.clip(np.rint(by), 0, b.shape[0] - 1).astype(int)
        inside &= ~bad_b[byi, bxi]
        if inside.sum() < 256:
            raise ValueError("the refinement left the overlap")
        warped = ndimage.map_coordinates(coeffs, [by, bx], order=3, prefilter=False,
                                         mode="nearest")
        # photometric model a ~ p(x, y) * b + offset: p is the smooth ratio of the views'
        # gains and vignetting over the overlap, refitted at every step (linear least squares)
        design = np.concatenate([poly * warped[:, None], np.ones((warped.size, 1))], axis=1)
        normal = design[inside].T @ design[inside]
        rhs = design[inside].T @ template[inside]
        coef = np.linalg.lstsq(normal, rhs, rcond=None)[0]
        err = np.where(inside, design @ coef - template, 0.0)
        # Huber weights: occlusions, ghosts or clipped pixels do not pull the fit
        sigma = 1.4826 * float(np.median(np.abs(err[inside]))) + 1e-12
        weight = np.where(inside, np.minimum(1.0, 3.0 * sigma / np.maximum(np.abs(err), 1e-30)),
                          0.0)
        use = inside
        weighted = steepest * weight[:, None]
        dp = np.linalg.solve(weighted.T @ steepest, weighted.T @ err)
        if motion == "translation":
            dp = np.array([0.0, 0.0, dp[0], 0.0, 0.0, dp[1], 0.0, 0.0])
        update = np.array([[1 + dp[0], dp[1], dp[2]], [dp[3], 1 + dp[4], dp[5]],
                           [dp[6], dp[7], 1.0]])
        g = g @ np.linalg.inv(update)
        g /= g[2, 2]
        step_px = float(np.abs(dp).max() * scale)
        if step_px < tol_px:
            break
    h_new = from_norm @ np.linalg.inv(g)
    info = {"photometric_iterations": done, "photometric_step_px": step_px,
            "photometric_rms": float(np.sqrt(np.mean(err[use] ** 2))),
            "photometric_points": int(use.sum())}
    return h_new / h_new[2, 2], info


def refine_homography(a: np.ndarray, b: np.ndarray, h_ab: np.ndarray, *,
                      max_points: int = 400_000, iterations: int = 30, degree: int = 4,
                      tol_px: float = 1e-3,
                      motion: str = "homography") -> tuple[np.ndarray, dict]:
    """Refine a homography by direct photometric least squares over the whole overlap.

    Inverse-compositional Gauss-Newton (Baker-Matthews) on ``a(x) = p(x) b(H^-1 x) + o``, with
    b resampled by cubic B-splines (exact for band-limited data, unlike bilinear warps whose
    interpolation error biases the fit), a smooth photometric ratio ``p`` (2-D polynomial of
    ``degree`` over the overlap: relative gain and vignetting) and offset ``o`` refitted at
    every step, Huber weights, and coordinates normalised to the overlap. Coarse pyramid levels
    (factor 2) are used first for views larger than 1024 px.

    Parameters
    ----------
    a, b : (rows, cols) views (NaN = no data); b's pixels map into a's by ``h_ab``.
    h_ab : (3, 3) initial homography (b pixels -> a pixels), within a few px.
    max_points : at most this many overlap pixels are used per level (a regular subgrid).
    iterations : Gauss-Newton steps per level.
    degree : degree of the photometric ratio polynomial.
    tol_px : stop when the update moves the overlap's corners by less than this (px).
    motion : "homography" (8 parameters) or "translation" (only the shift is updated).

    Returns
    -------
    h_ab : (3, 3) refined homography, ``h_ab[2, 2] == 1``.
    info : ``photometric_iterations``, ``photometric_step_px`` (last update), ``photometric_rms``
        (residual, image units), ``photometric_points``.

    Raises
    ------
    ValueError
        When the overlap is too small or the refinement runs away (more than 5 % of the view
        size from ``h_ab``); the caller keeps its initial estimate.
    """
    if motion not in MODELS:
        raise ValueError(f"motion must be one of {MODELS}, got {motion!r}")
    valid_a, valid_b = np.isfinite(a), np.isfinite(b)
    fa = fill_nan(np.asarray(a, np.float64))
    fb = fill_nan(np.asarray(b, np.float64))
    h = np.asarray(h_ab, np.float64) / h_ab[2, 2]
    levels = int(max(0, np.ceil(np.log2(max(a.shape) / 1024))))
    info: dict = {}
    for level in range(levels, -1, -1):
        if level:
            la, lb = fa, fb
            for _ in range(level):
                la, lb = cv2.pyrDown(la), cv2.pyrDown(lb)
            va = cv2.resize(valid_a.astype(np.uint8), la.shape[::-1],
                            interpolation=cv2.INTER_NEAREST).astype(bool)
            vb = cv2.resize(valid_b.astype(np.uint8), lb.shape[::-1],
                            interpolation=cv2.INTER_NEAREST).astype(bool)
        else:
            la, lb, va, vb = fa, fb, valid_a, valid_b
        down = np.diag([0.5**level, 0.5**level, 1.0])  # pyrDown: level pixel = full pixel / 2^l
        h_level, info = _refine_level(la, lb, va, vb, down @ h @ np.linalg.inv(down),
                                      max_points=max_points, iterations=iterations,
                                      degree=degree, tol_px=tol_px * 0.5**level,
                                      motion=motion)
        h = np.linalg.inv(down) @ h_level @ down
        h /= h[2, 2]
    rows, cols = b.shape
    corners = np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
    moved = cv2.perspectiveTransform(corners.reshape(-1, 1, 2), h) - cv2.perspectiveTransform(
        corners.reshape(-1, 1, 2), np.asarray(h_ab, np.float64) / h_ab[2, 2])
    if not np.isfinite(moved).all() or np.abs(moved).max() > 0.05 * max(rows, cols):
        raise ValueError("the photometric refinement ran away from the feature estimate")
    return h, info


def estimate_homography(a: np.ndarray, b: np.ndarray, *, direction: str = "h",
                        min_inliers: int = 12, ransac_px: float = 2.0,
                        min_correlation: float = 0.4,
                        prior: tuple[float, float] | None = None,
                        tolerance_px: float | None = None,
                        max_overlap: float = 0.7) -> tuple[np.ndarray, dict]:
    """Homography mapping view b's pixels to view a's, from SIFT + RANSAC + photometric
    refinement. With ``prior`` = expected shift (dy, dx), only matches displaced by it within
    ``tolerance_px`` (default 5 % of the view, >= 8 px) are kept: a periodic scene's false
    matches, a period away, are left out. A fit that lays view b over more than ``max_overlap``
    of view a (or not after it at all) is refused: on a periodic scene that is a false match.

    Returns
    -------
    h_ab : (3, 3) float64 with ``h_ab[2, 2] == 1``.
    info : dict with ``matches``, ``inliers``, ``reprojection_rms_px`` (RANSAC inliers under the
        final homography), ``correlation``, ``refinement``.
    """
    if direction not in ("h", "v"):
        raise ValueError(f"direction must be 'h' or 'v', got {direction!r}")
    ua, ub = _to_uint8(a), _to_uint8(b)
    sift = cv2.SIFT_create(nfeatures=8000, contrastThreshold=0.01)

    def data_mask(view):  # no features on the edges of no-data regions
        valid = np.isfinite(view)
        return None if valid.all() else ndimage.binary_erosion(valid, iterations=4).astype(
            np.uint8)

    ka, da = sift.detectAndCompute(ua, data_mask(a))
    kb, db = sift.detectAndCompute(ub, data_mask(b))
    if da is None or db is None or len(ka) < min_inliers or len(kb) < min_inliers:
        raise InputError(f"too few features ({len(ka)} and {len(kb)}) to fit a homography; the "
                         "views have no texture; try --model translation")
    knn = cv2.BFMatcher(cv2.NORM_L2).knnMatch(db, da, k=2)
    good = [m for m, *rest in knn if rest and m.distance < 0.75 * rest[0].distance]
    pb = np.float32([kb[m.queryIdx].pt for m in good]).reshape(-1, 2)
    pa = np.float32([ka[m.trainIdx].pt for m in good]).reshape(-1, 2)
    axis = 0 if direction == "h" else 1
    ahead = pa[:, axis] - pb[:, axis] > 0  # b lies after a: its points sit later in a
    if prior is not None:
        tol = tolerance_px if tolerance_px is not None else max(8.0, 0.05 * max(a.shape))
        shift = pa - pb
        ahead &= (np.abs(shift[:, 0] - prior[1]) <= tol) & (np.abs(shift[:, 1] - prior[0]) <= tol)
    pa, pb = pa[ahead], pb[ahead]
    if len(pa) < min_inliers:
        raise InputError(f"only {len(pa)} feature matches in the expected overlap direction; the "
                         "views may not overlap or have no texture")
    h, inl = cv2.findHomography(pb, pa, cv2.RANSAC, ransac_px, maxIters=5000, confidence=0.999)
    if h is None or inl is None or int(inl.sum()) < min_inliers:
        n_in = 0 if inl is None else int(inl.sum())
        raise InputError(f"only {n_in} RANSAC inliers (need {min_inliers}); the views may not "
                         "overlap or have no texture")
    inl = inl.ravel().astype(bool)
    # least squares (Levenberg-Marquardt) on the RANSAC inliers: a better start than the
    # minimal-sample model RANSAC returns
    h_ls, _ = cv2.findHomography(pb[inl], pa[inl], 0)
    h = h_ls if h_ls is not None else h
    h = h / h[2, 2]
    ha, hb = _highpass(a), _highpass(b)
    before = _aligned_correlation(ha, hb, h, a, b)
    refined, method, photometric = h, "ransac", {}
    try:
        candidate, photometric = refine_homography(a, b, h)
        after = _aligned_correlation(ha, hb, candidate, a, b)
        if np.isfinite(after) and after >= before - 0.01:
            refined, method = candidate, "photometric"
    except ValueError:
        pass
    proj = cv2.perspectiveTransform(pb[inl].reshape(-1, 1, 2).astype(np.float64), refined)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - pa[inl]) ** 2, axis=1))))
    correlation = _aligned_correlation(ha, hb, refined, a, b)
    if not np.isfinite(correlation) or correlation < min_correlation:
        raise InputError(f"no reliable overlap found between the views (normalised correlation "
                         f"{correlation:.2f} < {min_correlation} after the homography fit)")
    size = a.shape[1 - axis]  # along the overlap direction: width for "h", height for "v"
    centre = np.array([[[(b.shape[1] - 1) / 2, (b.shape[0] - 1) / 2]]])
    step = float(cv2.perspectiveTransform(centre, refined)[0, 0, axis] - centre[0, 0, axis])
    overlap = 1.0 - step / size
    if not 0 < overlap <= max_overlap:
        raise InputError(f"the homography lays one view {100 * overlap:.0f} % over the other "
                         f"(at most {100 * max_overlap:.0f} % expected): a false match, as a "
                         "periodic scene gives; use --overlap or --rig")
    info = {"matches": int(len(pa)), "inliers": int(inl.sum()), "reprojection_rms_px": rms,
            "correlation": correlation, "refinement": method, "overlap_fraction": overlap,
            **photometric}
    return refined, info


# ---------------------------------------------------------------------------------------------
# global solve, warping, gains, blending
def _difference_row(a: int, b: int, n_views: int) -> np.ndarray:
    """Design-matrix row of a pair measurement x_b - x_a, with view 0 fixed (x_0 = 0)."""
    row = np.zeros(n_views - 1)
    if b:
        row[b - 1] += 1
    if a:
        row[a - 1] -= 1
    return row


def _solve_translations(measured: list[tuple[int, int, np.ndarray]], n_views: int):
    """Least-squares positions p_k (p_0 = 0) from pair measurements p_b - p_a = d_ab."""
    m = np.array([_difference_row(a, b, n_views) for a, b, _ in measured])
    r = np.array([d for _, _, d in measured])
    pos, *_ = np.linalg.lstsq(m, r, rcond=None)
    closure = float(np.sqrt(np.mean(np.sum((m @ pos - r) ** 2, axis=1))))
    return np.vstack([np.zeros(2), pos]), closure


def _canvas(transforms: list[np.ndarray], shape: tuple[int, int]) -> tuple[np.ndarray, tuple]:
    """Translation view-0 coordinates -> panorama pixels, and the panorama (rows, cols)."""
    rows, cols = shape
    corners = np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
    pts = np.concatenate([cv2.perspectiveTransform(corners.reshape(-1, 1, 2), t).reshape(-1, 2)
                          for t in transforms])
    x0, y0 = np.floor(pts.min(axis=0) + 1e-6)
    x1, y1 = np.floor(pts.max(axis=0) + 1e-6)
    out_shape = (int(y1 - y0) + 1, int(x1 - x0) + 1)
    if out_shape[0] * out_shape[1] > 16 * rows * cols * len(transforms):
        raise InputError(f"the transforms spread the views over {out_shape[1]} x {out_shape[0]} "
                         "px; the registration failed (views without a true overlap?)")
    return _translation_matrix(-y0, -x0), out_shape


def _footprint(m: np.ndarray, shape: tuple[int, int], out_shape: tuple[int, int]):
    """The canvas box (row slice, column slice) a view of ``shape`` covers under ``m`` (view
    pixels -> canvas pixels), with 4 px for the resampling kernels, and ``m`` into that box."""
    rows, cols = shape
    corners = np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
    pts = cv2.perspectiveTransform(corners.reshape(-1, 1, 2), m).reshape(-1, 2)
    x0, y0 = (max(0, int(np.floor(v)) - 4) for v in pts.min(axis=0))
    x1 = min(out_shape[1], int(np.ceil(pts[:, 0].max())) + 5)
    y1 = min(out_shape[0], int(np.ceil(pts[:, 1].max())) + 5)
    x1, y1 = max(x1, x0 + 1), max(y1, y0 + 1)
    return (slice(y0, y1), slice(x0, x1)), _translation_matrix(-y0, -x0) @ m


def _bounding_box(mask: np.ndarray) -> tuple[slice, slice] | None:
    """Smallest (row slice, column slice) holding every True pixel, or None."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def _feather_weight(valid: np.ndarray) -> np.ndarray:
    """Distance (px) to the nearest invalid pixel or the view's border, float32."""
    if valid.all():  # the distance to the border, without a distance transform
        rows, cols = valid.shape
        to_y = np.minimum(np.arange(1, rows + 1), np.arange(rows, 0, -1)).astype(np.float32)
        to_x = np.minimum(np.arange(1, cols + 1), np.arange(cols, 0, -1)).astype(np.float32)
        return np.minimum(to_y[:, None], to_x[None, :])
    padded = np.pad(valid, 1)
    return ndimage.distance_transform_edt(padded)[1:-1, 1:-1].astype(np.float32)


def _warp(image: np.ndarray, m: np.ndarray, out_shape: tuple[int, int], *, interp: int,
          border: int = cv2.BORDER_REPLICATE) -> np.ndarray:
    size = (out_shape[1], out_shape[0])
    if np.allclose(m[2], [0, 0, 1]):
        return cv2.warpAffine(image, m[:2].astype(np.float64), size, flags=interp,
                              borderMode=border, borderValue=0)
    return cv2.warpPerspective(image, m, size, flags=interp, borderMode=border, borderValue=0)


def _multiband(images: np.ndarray, weights: np.ndarray, fallback: np.ndarray,
               levels: int = 5) -> np.ndarray:
    """Burt-Adelson blend of (V, rows, cols) images with seam masks (winner-takes-all weights)."""
    rows, cols = fallback.shape
    levels = max(1, min(levels, int(np.log2(max(2, min(rows, cols) // 16)))))
    winner = np.argmax(weights, axis=0)
    covered = weights.max(axis=0) > 0
    num = None
    den = None
    for k in range(images.shape[0]):
        img = np.where(weights[k] > 0, images[k], fallback).astype(np.float32)
        mask = ((winner == k) & covered).astype(np.float32)
        gauss_img, gauss_mask = [img], [mask]
        for _ in range(levels):
            gauss_img.append(cv2.pyrDown(gauss_img[-1]))
            gauss_mask.append(cv2.pyrDown(gauss_mask[-1]))
        lap = []
        for lvl in range(levels):
            size = (gauss_img[lvl].shape[1], gauss_img[lvl].shape[0])
            lap.append(gauss_img[lvl] - cv2.pyrUp(gauss_img[lvl + 1], dstsize=size))
        lap.append(gauss_img[-1])
        terms = [lp * gm for lp, gm in zip(lap, gauss_mask, strict=True)]
        num = terms if num is None else [n + t for n, t in zip(num, terms, strict=True)]
        den = gauss_mask if den is None else [d + g for d, g in zip(den, gauss_mask, strict=True)]
    bands = [n / np.maximum(d, 1e-6) for n, d in zip(num, den, strict=True)]
    out = bands[-1]
    for lvl in range(levels - 1, -1, -1):
        size = (bands[lvl].shape[1], bands[lvl].shape[0])
        out = cv2.pyrUp(out, dstsize=size) + bands[lvl]
    return out


def _longest_run(flags: np.ndarray) -> tuple[int, int] | None:
    """[start, stop) of the longest run of True in a 1-D boolean array, or None."""
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    if edges.size == 0:
        return None
    starts, stops = edges[::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])


def _block_residual(pano_a: np.ndarray, pano_b: np.ndarray, both: np.ndarray) -> float | None:
    """RMS (px) of local shifts left between two warped views, over blocks of their overlap."""
    from skimage.registration import phase_cross_correlation

    ys, xs = np.nonzero(both)
    if ys.size < 1024:
        return None
    y0, y1, x0, x1 = ys.min() + 2, ys.max() - 1, xs.min() + 2, xs.max() - 1
    if y1 - y0 < 32 or x1 - x0 < 32:
        return None
    ok = both[y0:y1, x0:x1]
    ha = _highpass(np.where(ok, pano_a[y0:y1, x0:x1], np.nan))
    hb = _highpass(np.where(ok, pano_b[y0:y1, x0:x1], np.nan))
    long_axis = 0 if (y1 - y0) >= (x1 - x0) else 1
    n_blocks = max(1, min(4, (ha.shape[long_axis]) // 64))
    shifts = []
    for block in range(n_blocks):
        sl = [slice(None), slice(None)]
        length = ha.shape[long_axis]
        sl[long_axis] = slice(block * length // n_blocks, (block + 1) * length // n_blocks)
        # an overlap that is not a rectangle (homography, undistorted views): keep the longest
        # run of lines across the block that lie wholly inside it
        full = ok[tuple(sl)].all(axis=long_axis)
        run = _longest_run(full)
        if run is None or run[1] - run[0] < 16:
            continue
        sl[1 - long_axis] = slice(*run)
        sl = tuple(sl)
        if ha[sl].std() == 0:
            continue
        shift, _, _ = phase_cross_correlation(ha[sl], hb[sl], upsample_factor=20)
        shifts.append(shift)
    if not shifts:
        return None
    return float(np.sqrt(np.mean(np.sum(np.square(shifts), axis=1))))


def stitch(views: np.ndarray | Sequence[np.ndarray], *, layout: str = "auto",
           model: str = "translation", distortion_k1: float = 0.0,
           transform: dict | None = None, blend: str = "feather", match_gain: bool = True,
           max_overlap: float = 0.7, min_overlap_px: int = 16,
           min_correlation: float = 0.4, rig: PrismRig | None = None,
           overlap: float | None = None, overlap_tolerance: float = 0.1,
           tolerance_px: float | None = None) -> tuple[np.ndarray, dict]:
    """Stitch 2 or 4 overlapping views into one extended-FOV panorama.

    Parameters
    ----------
    views : (V, rows, cols) or (V, C, rows, cols) array, or a sequence of V equal arrays;
        V = 2 (side by side or one above the other) or 4 (2 x 2, row-major). NaN = no data.
    layout : "1x2", "2x1", "2x2" or "auto" (4 views -> 2x2; 2 views -> the direction whose
        overlap correlates best).
    model : "translation" or "homography".
    distortion_k1 : known constant radial distortion removed from every view first (see
        :func:`undistort`); 0 = none.
    transform : a previous report's transform (``report["transform"]``) to reapply to views of
        the same rig instead of registering them again.
    blend : "feather" (weights = distance to the view's edge) or "multiband".
    match_gain : match per-view, per-channel exposure from the overlaps (view 0 is the reference).
    max_overlap, min_overlap_px, min_correlation : registration search limits, see
        :func:`estimate_translation`.
    rig : the prism rig (:class:`plenocli.prismrig.PrismRig`, one entry per view): every view
        is first resampled into the common undistorted frame (the prisms' constant distortion
        cancelled), and each pair is searched only within ``tolerance_px`` (default 5 % of the
        view, >= 8 px) of the position the rig predicts.
    overlap, overlap_tolerance : without a rig, the expected overlap (fraction of the view
        along the stitching direction) and the tolerance on it (same unit): the search is
        restricted to it.

    Returns
    -------
    panorama : (rows', cols') float32, or (C, rows', cols') for colour views; NaN where no view
        covers the panorama.
    report : dict (JSON-ready): ``model``, ``layout``, ``transform`` (reusable), ``pairs`` (per
        neighbour pair: shift or homography, overlap, correlation, inliers, residual_px),
        ``gains``, ``residual_px``, ``closure_px``, ``panorama_shape``, ``origin_px``,
        ``coverage_fraction``.
    """
    stack, colour = as_view_stack(views)
    n_views, n_chan, rows, cols = stack.shape
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    if blend not in BLENDS:
        raise ValueError(f"blend must be one of {BLENDS}, got {blend!r}")
    if layout != "auto" and layout not in LAYOUTS:
        raise ValueError(f"layout must be 'auto' or one of {sorted(LAYOUTS)}, got {layout!r}")
    if layout != "auto" and LAYOUTS[layout][0] * LAYOUTS[layout][1] != n_views:
        raise InputError(f"layout {layout} needs {LAYOUTS[layout][0] * LAYOUTS[layout][1]} views, "
                         f"got {n_views}")
    if overlap is not None and not 0 < overlap < 1:
        raise ValueError(f"overlap must be in (0, 1), got {overlap}")
    if not 0 < overlap_tolerance < 1:
        raise ValueError(f"overlap_tolerance must be in (0, 1), got {overlap_tolerance}")
    view_shape = (rows, cols)
    if transform is not None and rig is None and transform.get("rig"):
        try:
            rig = PrismRig.from_dict(transform["rig"])
        except ValueError as err:
            raise InputError(f"the transform's rig is not valid ({err})") from err
    if distortion_k1:
        stack = np.stack([[undistort(ch, distortion_k1) for ch in v] for v in stack])
    origins = None
    if rig is not None:
        if len(rig.views) != n_views:
            raise InputError(f"the rig describes {len(rig.views)} views but {n_views} are "
                             "given; list one rig view per input view, in order")
        try:
            stack, origins = undistort_views(stack, rig)
        except ValueError as err:
            raise InputError(f"the rig does not fit these views: {err}") from err
        rows, cols = stack.shape[-2:]
        if layout == "auto":
            d = origins[1] - origins[0]
            layout = "2x2" if n_views == 4 else ("1x2" if abs(d[1]) >= abs(d[0]) else "2x1")
    if n_chan > 1:
        with warnings.catch_warnings():  # no-data pixels (all NaN) stay NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            luma = np.nanmean(stack, axis=1)
    else:
        luma = stack[:, 0]
    for k in range(n_views):
        if not np.isfinite(luma[k]).any():
            raise InputError(f"view {k} holds no data (all NaN)")
        if float(np.nanstd(luma[k])) == 0.0:
            raise InputError(f"view {k} has no texture (constant image); stitching needs "
                             "structure in the overlap")
    search = dict(max_overlap=max_overlap, min_overlap_px=min_overlap_px,
                  min_correlation=min_correlation)
    pair_info: list[dict] = []
    closure = None
    if transform is not None:
        transforms, layout, source = _check_transform(transform, n_views, view_shape, model)
    else:
        source = "estimated"
        if layout == "auto":
            layout = "2x2" if n_views == 4 else _auto_layout(luma, search, overlap,
                                                              overlap_tolerance)
        priors = _priors(layout, (rows, cols), origins, overlap, overlap_tolerance,
                         tolerance_px)
        transforms, pair_info, closure = _register(luma, layout, model, search, priors)
    offset, pano_shape = _canvas(transforms, (rows, cols))
    warped = np.full((n_views, n_chan) + pano_shape, np.nan, np.float32)
    weights = np.zeros((n_views,) + pano_shape, np.float32)
    for k in range(n_views):
        # each view is resampled only into its footprint on the canvas (the rest stays empty)
        box, m = _footprint(offset @ transforms[k], (rows, cols), pano_shape)
        box_shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
        valid = np.isfinite(stack[k]).all(axis=0)
        cover = _warp(valid.astype(np.float32), m, box_shape, interp=cv2.INTER_LINEAR,
                      border=cv2.BORDER_CONSTANT) > 0.999
        weights[k][box] = np.where(cover, _warp(_feather_weight(valid), m, box_shape,
                                                interp=cv2.INTER_LINEAR), 0)
        for c in range(n_chan):
            img = _warp(fill_nan(stack[k, c]), m, box_shape, interp=cv2.INTER_LANCZOS4)
            warped[k, c][box] = np.where(cover, img, np.nan)
    gains = np.ones((n_views, n_chan))
    pairs = _pairs(layout)
    if match_gain:
        gains = _match_gains(warped, weights, pairs)
        warped *= gains[:, :, None, None].astype(np.float32)
    total = weights.sum(axis=0)
    covered = total > 0
    if covered.any():  # trim the canvas to what the views cover (rig canvases are generous)
        rows_any = np.flatnonzero(covered.any(axis=1))
        cols_any = np.flatnonzero(covered.any(axis=0))
        r0, r1, c0, c1 = rows_any[0], rows_any[-1] + 1, cols_any[0], cols_any[-1] + 1
        if (r0, c0, r1, c1) != (0, 0, *pano_shape):
            warped, weights = warped[..., r0:r1, c0:c1], weights[:, r0:r1, c0:c1]
            total, covered = total[r0:r1, c0:c1], covered[r0:r1, c0:c1]
            pano_shape = (int(r1 - r0), int(c1 - c0))
            offset = offset.copy()
            offset[0, 2] -= c0
            offset[1, 2] -= r0
    panorama = np.full((n_chan,) + pano_shape, np.nan, np.float32)
    inv_total = 1.0 / np.maximum(total, 1e-12)
    for c in range(n_chan):
        # view by view: one canvas-sized temporary instead of a (views, canvas) stack
        feather = np.zeros(pano_shape, np.float32)
        for k in range(n_views):
            feather += np.nan_to_num(warped[k, c]) * weights[k]
        feather *= inv_total
        if blend == "multiband":
            feather = _multiband(np.nan_to_num(warped[:, c]), weights, feather)
        panorama[c] = np.where(covered, feather, np.nan)
    del inv_total
    residuals = []
    for (a, b, _), info in zip(pairs, pair_info or [{} for _ in pairs], strict=True):
        both = (weights[a] > 0) & (weights[b] > 0)
        box = _bounding_box(both)
        res = None if box is None else _block_residual(
            warped[(a, slice(None)) + box].mean(axis=0),
            warped[(b, slice(None)) + box].mean(axis=0), both[box])
        info["residual_px"] = res
        info["overlap_px_area"] = int(both.sum())
        if res is not None:
            residuals.append(res)
    if transform is not None:
        pair_info = [{"views": [a, b], "direction": d} for a, b, d in pairs]
    axis_px, field_deg = None, None
    if rig is not None:
        axis_px, field_deg = _rig_axis_and_field(rig, view_shape, origins, offset, panorama)
    report = {
        "model": model, "layout": layout, "n_views": n_views, "channels": n_chan if colour else 1,
        "view_shape": list(view_shape), "distortion_k1": distortion_k1, "blend": blend,
        "rig": rig.to_dict() if rig is not None else None,
        "canvas_shape": [rows, cols] if rig is not None else None,
        "canvas_origins_px": origins.tolist() if origins is not None else None,
        "axis_px": axis_px, "field_deg": field_deg,
        "transform_source": source,
        "transform": {"model": model, "layout": layout, "view_shape": list(view_shape),
                      "distortion_k1": distortion_k1,
                      "rig": rig.to_dict() if rig is not None else None,
                      "view_to_reference": [t.tolist() for t in transforms]},
        "shifts_px": [[float(t[1, 2]), float(t[0, 2])] for t in transforms],
        "pairs": pair_info,
        "gains": gains.tolist(),
        "residual_px": float(np.sqrt(np.mean(np.square(residuals)))) if residuals else None,
        "closure_px": closure,
        "panorama_shape": list(pano_shape),
        "origin_px": [float(offset[1, 2]), float(offset[0, 2])],
        "coverage_fraction": float(covered.mean()),
    }
    return (panorama if colour else panorama[0]), report


def _rig_axis_and_field(rig: PrismRig, view_shape: tuple[int, int], origins: np.ndarray,
                        offset: np.ndarray, panorama: np.ndarray):
    """Panorama pixel [row, col] of the main lens's optical axis, and the panorama's angular
    field {"x", "y"} (deg): the covered span along the row (column) through each view's centre,
    the widest of them (the prisms bend the views' outer edges, so the span depends on the line).
    """
    from plenocli.prismrig import view_to_common

    rows, cols = view_shape
    shift = -origins[0] + [offset[1, 2], offset[0, 2]]  # common -> panorama (view 0 reference)
    axis = np.array([(rows - 1) / 2, (cols - 1) / 2]) + shift
    pix = rig.sensor_mm / cols
    dist = rig.image_distance_mm
    covered = np.isfinite(panorama).all(axis=0) if panorama.ndim == 3 else np.isfinite(panorama)
    field: dict = {"x": None, "y": None}
    for k in range(len(rig.views)):
        cx, cy = view_to_common(rig, k, np.array([(cols - 1) / 2]), np.array([(rows - 1) / 2]),
                                view_shape)
        centre = np.array([cy[0], cx[0]]) + shift
        for name, line, c in (("x", covered[int(round(centre[0])), :], axis[1]),
                              ("y", covered[:, int(round(centre[1]))], axis[0])):
            idx = np.nonzero(line)[0]
            if idx.size == 0:
                continue
            lo, hi = idx.min() - 0.5 - c, idx.max() + 0.5 - c  # pixel edges
            span = float(np.degrees(np.arctan(hi * pix / dist) - np.arctan(lo * pix / dist)))
            field[name] = span if field[name] is None else max(field[name], span)
    return axis.tolist(), field


def _priors(layout: str, shape: tuple[int, int], origins: np.ndarray | None,
            overlap: float | None, overlap_tolerance: float, tolerance_px: float | None
            ) -> dict:
    """Expected shift (dy, dx) and search tolerance (px) per neighbour pair, or None."""
    rows, cols = shape
    priors = {}
    for a, b, direction in _pairs(layout):
        if origins is not None:
            d = origins[b] - origins[a]
            priors[(a, b)] = ((float(d[0]), float(d[1])), tolerance_px)
        elif overlap is not None:
            size = cols if direction == "h" else rows
            shift = (0.0, size * (1 - overlap)) if direction == "h" else (size * (1 - overlap),
                                                                           0.0)
            tol = tolerance_px if tolerance_px is not None else overlap_tolerance * size
            priors[(a, b)] = (shift, tol)
        else:
            priors[(a, b)] = (None, None)
    return priors


def _auto_layout(luma: np.ndarray, search: dict, overlap: float | None = None,
                 overlap_tolerance: float = 0.1) -> str:
    best, best_corr, errors = None, -np.inf, []
    for layout, direction in (("1x2", "h"), ("2x1", "v")):
        (prior, tol), = _priors(layout, luma.shape[1:], None, overlap, overlap_tolerance,
                                None).values()
        try:
            _, _, info = estimate_translation(luma[0], luma[1], direction=direction, prior=prior,
                                              tolerance_px=tol, **search)
        except InputError as err:
            errors.append(str(err))
            continue
        if info["correlation"] > best_corr:
            best, best_corr = layout, info["correlation"]
    if best is None:
        raise InputError(f"no overlap found side by side nor one above the other ({errors[0]})")
    return best


def _register(luma: np.ndarray, layout: str, model: str, search: dict, priors: dict):
    n_views = luma.shape[0]
    pair_info = []
    measured = []
    for a, b, direction in _pairs(layout):
        prior, tol = priors[(a, b)]
        try:
            if model == "translation":
                dy, dx, info = estimate_translation(luma[a], luma[b], direction=direction,
                                                    prior=prior, tolerance_px=tol, **search)
                measured.append((a, b, np.array([dy, dx])))
                info["shift_px"] = [dy, dx]
            else:
                h, info = estimate_homography(luma[a], luma[b], direction=direction,
                                              min_correlation=search["min_correlation"],
                                              prior=prior, tolerance_px=tol,
                                              max_overlap=search["max_overlap"])
                measured.append((a, b, h))
                info["homography"] = h.tolist()
        except InputError as err:
            raise InputError(f"views {a} and {b}: {err}") from err
        if prior is not None:
            info["expected_shift_px"] = list(prior)
        pair_info.append({"views": [a, b], "direction": direction, **info})
    closure = None
    if model == "translation":
        pos, closure = _solve_translations(measured, n_views)
        transforms = [_translation_matrix(*p) for p in pos]
        if n_views == 2:
            closure = None
    else:
        h = {(a, b): m for a, b, m in measured}
        transforms = [np.eye(3)] * n_views
        transforms[1] = h[(0, 1)]
        if n_views == 4:
            transforms[2] = h[(0, 2)]
            via_1 = h[(0, 1)] @ h[(1, 3)]
            via_2 = h[(0, 2)] @ h[(2, 3)]
            transforms[3] = via_1 / via_1[2, 2]
            rows, cols = luma.shape[1:]
            corners = np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
            p1 = cv2.perspectiveTransform(corners.reshape(-1, 1, 2), via_1)
            p2 = cv2.perspectiveTransform(corners.reshape(-1, 1, 2), via_2 / via_2[2, 2])
            closure = float(np.max(np.linalg.norm((p1 - p2).reshape(-1, 2), axis=1)))
    return transforms, pair_info, closure


def _check_transform(transform: dict, n_views: int, shape: tuple[int, int], model: str):
    try:
        mats = [np.asarray(t, dtype=np.float64) for t in transform["view_to_reference"]]
        layout = transform["layout"]
        view_shape = tuple(transform["view_shape"])
    except (KeyError, TypeError, ValueError) as err:
        raise InputError(f"the transform is not a plenocli stitch transform (missing or bad "
                         f"{err}); save one with --transform-out") from err
    if len(mats) != n_views or any(m.shape != (3, 3) for m in mats):
        raise InputError(f"the transform holds {len(mats)} view transforms for {n_views} views")
    if view_shape != shape:
        raise InputError(f"the transform was made for views of {view_shape[1]} x {view_shape[0]} "
                         f"px, these are {shape[1]} x {shape[0]}; register them again")
    if transform.get("model", model) != model:
        raise InputError(f"the transform is a {transform.get('model')} model but --model is "
                         f"{model}; pass --model {transform.get('model')}")
    return mats, layout, "given"


def _match_gains(warped: np.ndarray, weights: np.ndarray,
                 pairs: list[tuple[int, int, str]]) -> np.ndarray:
    """Per-view, per-channel gains from overlap means (log least squares, view 0 fixed)."""
    n_views, n_chan = warped.shape[:2]
    gains = np.ones((n_views, n_chan))
    for c in range(n_chan):
        rows, rhs = [], []
        for a, b, _ in pairs:
            both = (weights[a] > 0) & (weights[b] > 0)
            both &= np.isfinite(warped[a, c]) & np.isfinite(warped[b, c])
            mean_a = float(warped[a, c][both].mean()) if both.any() else 0.0
            mean_b = float(warped[b, c][both].mean()) if both.any() else 0.0
            if mean_a <= 0 or mean_b <= 0:
                continue  # no usable overlap or signed data: leave this pair out
            rows.append(_difference_row(a, b, n_views))
            rhs.append(np.log(mean_a / mean_b))
        if rows:
            sol, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
            gains[1:, c] = np.exp(sol)
    return gains
