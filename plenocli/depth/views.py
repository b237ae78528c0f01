"""Disparity between the views of a dual-pixel (A/B) or quad-pixel (2 x 2 SAIs) capture.

The disparity d is the shift of B's content against A's along the baseline, in pixels, + when
B's content lies to the right of A's (quad-pixel: the right column S01, S11 against the left
one, and the bottom row S10, S11 against the top one, + downwards). Steps (docs/depth.md):

1. Photometry: each view is divided by its own slow level (the geometric mean over a Gaussian
   of sigma ``FLAT_SIGMA`` px), so what is left of the vignetting and of the A/B split after
   ``plenocli flat`` (or without it) does not bias the match; then both are smoothed by a
   small Gaussian. NaN pixels (no data) are left out of every window's sums and stay NaN.
2. Coarse: the windowed sum of squared differences of A(x) and B(x + d) for whole-pixel d in
   [-max, max] at full size, parabola through the minimum; a pixel with two clear minima (a
   texture repeating within the search) is unknown.
3. Refinement: Lucas-Kanade steps with symmetric warps (A moved by -d/2, B by +d/2, cubic
   interpolation), the gradient the mean of both: the asymmetric half-pupil blur of the two
   views (mirror images of each other) enters both sides alike instead of biasing one.
4. Confidence: 1 - best / median cost of the coarse curve (0 on textureless areas).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from plenocli.depth import MAX_DISPARITY
from plenocli.depth.level import FLAT_SIGMA, level  # noqa: F401  (FLAT_SIGMA: the stage)
from plenocli.depth.searchkernel import search_step

PRE_BLUR = 1.0
# share of a window's pixels with data in both views below which its pixel is unknown
MIN_DATA = 0.5
WINDOW = 15
# the coarse search's window, at full size: the WINDOW it had on the views shrunk by two (a
# 15 px window there, noisier at full size: the Pixel 4 pair's clear matches agreed 44 %)
COARSE_WINDOW = 2 * WINDOW + 1
LK_STEPS = 2
TILE_ROWS = 512
# A/B parallax runs along rows. Of the row search's clear matches, a pixel is one a vertical
# shift explains and no horizontal one does when, both fitted to the sub-pixel, the vertical
# cost is under POOR times the mean cost of the horizontal shifts tried and under CLEARLY
# times the horizontal one, which is over POOR. Where a horizontal shift fits, a slanted or
# striped texture lets a vertical one fit as well, and nothing says which is the parallax.
# Views side by side: 0-2.6 % (simulated bands of up to 10 px, six textures; grain and
# stripes at 0-60 degrees; the Pixel 4 pair 0.1-0.2 %; prism views looking apart 1.8 %); the
# same views transposed 24-99 % (Pixel 4: 27-29 %), which the row search read with clear
# confidence (2 px as 0.89)
MAX_VERTICAL_SHARE = 0.1
CLEARLY = 0.7
POOR = 0.1
# Where the texture runs mostly one way with a little of the other (a brick wall: long courses,
# short joints), a horizontal shift already fits a vertical one of about 1 px well (row cost
# 0.014 of the mean) and the rule above passes it. On windows with texture in both directions
# (the structure tensor's smaller eigenvalue at least TWO_WAY of the larger) no horizontal
# shift can stand in for a vertical one, so there a vertical fit better by CLEARLY is evidence,
# once the horizontal one leaves a residual: over FIT_FLOOR of the mean cost (in-focus views,
# where both fits leave only noise and interpolation, put either axis ahead by chance on
# 15-40 % of such windows). Side by side: 0-1.9 % of those windows (bands, oriented grain and
# stripes, natural images at 0-2 px, the Pixel 4 pair 0.0 %); turned, a brick wall at 0.6-3 px
# 99-100 %, natural images at 0.6 px 22-100 %. Counted when they are MIN_TEXTURED of the
# pixels (oriented grain has a few, 0.0-0.4 %, whose shares are chance).
TWO_WAY = 0.25
FIT_FLOOR = 0.01
CLEAR = 0.5  # confidence of a clear match (as lenslet.CLEAR_MATCH)
MIN_TEXTURED = 0.01  # share of clear matches below which views share no texture (the stage)
# larger views are checked on SAMPLE_SIDE x SAMPLE_SIDE blocks of SAMPLE_BLOCK px spread over
# the frame (about 4 Mpx: the whole frame of 30 Mpx took 1.4 s, 40 % of the map's time)
SAMPLE_BLOCK = 256
SAMPLE_SIDE = 8


@dataclass(frozen=True)
class Disparity:
    """Disparity (rows, cols) float32 px (NaN: unknown) and confidence (0..1); ``repeat_px``:
    where the texture repeats within the search (two shifts match clearly, so the pixel is
    unknown), how far apart they lie in px, else 0; ``no_data``: where a view has no data
    (NaN pixels, windows mostly NaN: ``_no_data``), so the disparity is unknown."""

    disparity: np.ndarray
    confidence: np.ndarray
    repeat_px: np.ndarray | None = None
    no_data: np.ndarray | None = None


def prepare(view: np.ndarray, shared: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """(the view divided by its level (``level``) and smoothed by PRE_BLUR; where it has
    data, None when every pixel has). Pixels without data (NaN) are filled from their
    neighbours for the smoothing and the warps (``data`` says to leave them out of every
    sum). ``shared``: where every view matched against this one has data, the pixels its
    level is taken from (the views' levels must see the same pixels: ``disparity_x``)."""
    v = np.asarray(view, np.float32)
    data = np.isfinite(v)
    v = np.where(data, v, 0.0).astype(np.float32)
    out = v / level(v, data if shared is None else data & shared)
    weight = None if data.all() else data.astype(np.float32)
    return _blur(out, weight, PRE_BLUR), None if weight is None else data


def _blur(img: np.ndarray, weight: np.ndarray | None, sigma: float) -> np.ndarray:
    """Gaussian of ``img`` over the pixels of ``weight`` 1 (all when None), normalised by the
    weights there: a pixel without data neither darkens nor brightens its neighbours; one
    with no data near takes 1, the divided views' level."""
    if weight is None:
        return cv2.GaussianBlur(img, (0, 0), sigma)
    num = cv2.GaussianBlur(img * weight, (0, 0), sigma)
    den = cv2.GaussianBlur(weight, (0, 0), sigma)
    return np.where(den > 1e-3, num / np.maximum(den, 1e-3), 1.0).astype(np.float32)


def _shift_x(img: np.ndarray, dx: np.ndarray, grid_x: np.ndarray, grid_y: np.ndarray,
             interpolation: int = cv2.INTER_CUBIC) -> np.ndarray:
    """img sampled at (x + dx, y) (dx a map), border replicated."""
    return cv2.remap(img, grid_x + dx, grid_y, interpolation, borderMode=cv2.BORDER_REPLICATE)


def _shift_whole(img: np.ndarray, d: int) -> np.ndarray:
    """img sampled at (x + d, y) for a whole number d, edge replicated."""
    if d == 0:
        return img
    out = np.empty_like(img)
    if d > 0:
        out[:, :-d] = img[:, d:]
        out[:, -d:] = img[:, -1:]
    else:
        out[:, -d:] = img[:, :d]
        out[:, :-d] = img[:, :1]
    return out


def _box(img: np.ndarray, side: int = WINDOW) -> np.ndarray:
    return cv2.boxFilter(img, -1, (side, side), normalize=True, borderType=cv2.BORDER_REFLECT)


def disparity_x(a: np.ndarray, b: np.ndarray, *, max_disparity: float = 4.0,
                check_rows: bool = True) -> Disparity:
    """Horizontal disparity of ``b`` against ``a`` (same shape, 2-D, NaN = no data);
    ValueError (``check_rows``) when their parallax runs along columns (see ``_check_rows``)."""
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"views must be two 2-D images of one shape, got {a.shape}, {b.shape}")
    if min(a.shape) < 2 * WINDOW:
        raise ValueError(f"views of {a.shape[1]} x {a.shape[0]} px (columns x rows) are too "
                         f"small for {WINDOW} px windows")
    if not (np.isfinite(max_disparity) and 0.5 <= max_disparity <= MAX_DISPARITY):
        raise ValueError(f"max_disparity must be 0.5 to {MAX_DISPARITY:g} px, got {max_disparity}")
    # both levels over the pixels both views have: a hole in one view only (a clipped
    # highlight) took its content out of that view's level alone, some 72 px around
    shared = np.isfinite(a) & np.isfinite(b)
    shared = None if shared.all() else shared
    (pa, ma), (pb, mb) = prepare(a, shared), prepare(b, shared)
    masks = None if ma is None and mb is None else \
        tuple(np.ones(a.shape, np.float32) if m is None else m.astype(np.float32)
              for m in (ma, mb))
    d = np.empty(a.shape, np.float32)
    conf = np.empty(a.shape, np.float32)
    repeat = np.empty(a.shape, np.float32)
    reach = int(np.ceil(max_disparity))
    if check_rows:
        _check_rows(pa, pb, reach)
    margin = WINDOW
    for top in range(0, a.shape[0], TILE_ROWS):  # tiles keep the working set small
        lo, hi = max(0, top - margin), min(a.shape[0], top + TILE_ROWS + margin)
        td, tc, tr = _tile(pa[lo:hi], pb[lo:hi], reach,
                           None if masks is None else tuple(m[lo:hi] for m in masks))
        keep = slice(top - lo, top - lo + min(TILE_ROWS, a.shape[0] - top))
        d[top:top + TILE_ROWS] = td[keep]
        conf[top:top + TILE_ROWS] = tc[keep]
        repeat[top:top + TILE_ROWS] = tr[keep]
    no_data = _no_data(masks) if masks is not None else np.zeros(a.shape, bool)
    lost = no_data.copy()
    # a best shift pinned at the search bound is no minimum, and a cost that does not vary
    # with the shift (confidence 0: no texture) measures nothing
    lost |= (np.abs(d) >= reach - 1e-3) | (np.abs(d) > max_disparity) | ~(conf > 0)
    # two shifts that both match clearly (a texture repeating within the search) say nothing
    # of which one is the parallax: 7.3 px stripes 1 px apart, searched to 8, read -6.3
    lost |= repeat > 0
    # a window reaching past the frame's edge, in a or at the found shift in b, matched the
    # padding there: a patch at a simulated frame's corner read +7 px as -9.3, confidently.
    # The coarse search's windows, on the views shrunk by two, reach a whole WINDOW
    half = WINDOW
    rows, cols = a.shape
    with np.errstate(invalid="ignore"):
        x = np.arange(cols, dtype=np.float32)[None, :]
        y = np.arange(rows)[:, None]
        lost |= (x + np.minimum(d, 0) < half) | (x + np.maximum(d, 0) > cols - 1 - half)
        lost |= (y < half) | (y > rows - 1 - half)
    d[lost] = np.nan
    conf[lost] = 0.0
    return Disparity(d, conf, repeat, no_data)


def _no_data(masks: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Pixels without data in either view (NaN: clipped or unknown; they stay NaN), and
    pixels whose WINDOW holds data in both views on under MIN_DATA of its pixels. Each window
    leaves such pixels out of its sums (weights), so a scattered one costs only itself: a NaN
    poisoned its whole window before, and 1 % of them, scattered, left 9.6 % of the frame
    known (audit 18 F3)."""
    both = masks[0] * masks[1]
    return (both < 0.5) | (_box(both) < MIN_DATA)


def _check_rows(pa: np.ndarray, pb: np.ndarray, reach: int) -> None:
    """ValueError when B differs from A by a vertical shift rather than a horizontal one:
    views turned by 90 degrees (a portrait capture) or a sensor split top/bottom. The row
    search alone finds a best horizontal shift there too, with clear confidence, and it is
    wrong."""
    wrong = crossing(pa, pb, reach)
    if wrong:
        raise ValueError(f"the views' parallax runs along columns, not rows: a vertical shift "
                         f"explains {100 * wrong[0]:.0f} % of their {wrong[1]}, which no "
                         "horizontal one does (views side by side: under 3 %); disparity "
                         "is measured along rows, B's content right of A's: turn both "
                         "views by 90 degrees (a portrait capture, a sensor split "
                         "top/bottom) so that their baseline runs along rows; nothing was "
                         "written")


def crossing(pa: np.ndarray, pb: np.ndarray, reach: int) -> tuple[float, str] | None:
    """(share, of what) when B differs from A by a vertical shift that no horizontal one
    explains (over MAX_VERTICAL_SHARE of either share of ``vertical_share``: parallax along
    columns), else None. ``pa``, ``pb`` prepared."""
    for share, where in zip(vertical_share(pa, pb, reach),
                            ("clear matches", "clear matches on texture of two directions"),
                            strict=True):
        if share is not None and share > MAX_VERTICAL_SHARE:
            return share, where
    return None


def vertical_share(pa: np.ndarray, pb: np.ndarray, reach: int
                   ) -> tuple[float | None, float | None]:
    """Of the pixels the row search matches clearly (confidence >= 0.5, what the map gives
    with confidence), the share a vertical shift explains and no horizontal one does; and the
    same of those on texture of two directions (TWO_WAY, by their own rule, above). Each is
    None when under MIN_TEXTURED of the pixels count (the stage refuses views with too few
    clear matches as sharing no texture). On the views shrunk by two, as the coarse search.
    Costs at whole shifts do not do: a horizontal disparity of 1 px is 0.5 px there, which no
    whole shift fits, while on a slanted texture a whole vertical shift does (grain at 60
    degrees and stripes at 10-30 degrees from vertical read 91-100 % so)."""
    steps = (reach + 1) // 2 + 1
    counts = np.zeros(5, np.int64)  # pixels, clear, vertical, clear two-way, vertical there
    for block in _sample_blocks(pa.shape):
        size = (max(1, (block[1].stop - block[1].start) // 2),
                max(1, (block[0].stop - block[0].start) // 2))
        sa, sb = (cv2.resize(v[block], size, interpolation=cv2.INTER_AREA) for v in (pa, pb))
        row, conf, mean = _fitted_cost(sa, sb, steps)
        col = _fitted_cost(np.ascontiguousarray(sa.T), np.ascontiguousarray(sb.T), steps)[0].T
        # not the column search's clear matches: a white's row noise, opposite in A and
        # B = S - A, fits any vertical shift better than none
        sure = conf >= 0.5
        better = (col < CLEARLY * row) & (col < POOR * mean)
        two_way = sure & _two_way(sa)
        counts += [sure.size, sure.sum(), np.sum(better & sure & (row > POOR * mean)),
                   two_way.sum(), np.sum(better & two_way & (row > FIT_FLOOR * mean))]
    pixels, textured, vertical, two, two_vertical = (int(c) for c in counts)
    enough = MIN_TEXTURED * pixels
    return (vertical / textured if textured >= enough else None,
            two_vertical / two if two >= enough else None)


def _two_way(img: np.ndarray) -> np.ndarray:
    """Where the structure tensor over a WINDOW has its smaller eigenvalue at least TWO_WAY of
    the larger: texture of two directions."""
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=1)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=1)
    xx, yy, xy = _box(gx * gx), _box(gy * gy), _box(gx * gy)
    half_sum = 0.5 * (xx + yy)
    spread = np.sqrt(np.maximum(0.25 * (xx - yy) ** 2 + xy * xy, 0))
    return (half_sum - spread) > TWO_WAY * (half_sum + spread)


def _fitted_cost(pa: np.ndarray, pb: np.ndarray, reach: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Windowed SSD of A(x) against B(x + d) at the row search's sub-pixel best d (B sampled
    there, cubic), its confidence, and the mean cost of the whole shifts |s| <= reach."""
    d, conf, mean, _ = _search(pa, pb, reach)
    rows, cols = pa.shape
    grid_y = np.ascontiguousarray(np.broadcast_to(np.arange(rows, dtype=np.float32)[:, None],
                                                  (rows, cols)))
    moved = _shift_x(pb, d, np.arange(cols, dtype=np.float32)[None, :], grid_y)
    return _box((moved - pa) ** 2), conf, mean


def _sample_blocks(shape: tuple[int, int]) -> list[tuple[slice, slice]]:
    """The whole frame, or SAMPLE_SIDE x SAMPLE_SIDE blocks evenly spread over a larger one."""
    rows, cols = shape
    if rows * cols <= (SAMPLE_SIDE * SAMPLE_BLOCK) ** 2:
        return [(slice(0, rows), slice(0, cols))]
    side_r, side_c = min(rows, SAMPLE_BLOCK), min(cols, SAMPLE_BLOCK)
    tops = np.unique(np.linspace(0, rows - side_r, SAMPLE_SIDE).astype(int))
    lefts = np.unique(np.linspace(0, cols - side_c, SAMPLE_SIDE).astype(int))
    return [(slice(t, t + side_r), slice(c, c + side_c)) for t in tops for c in lefts]


def consistent_share(disparity: np.ndarray, confidence: np.ndarray, *,
                     clear: float = 0.5, tolerance: float = 1.0, reach: int = 3) -> float:
    """Share of the clear matches (confidence >= ``clear``) whose disparity agrees, within
    ``tolerance`` px, with the mean of the clear matches around them: in a square of
    ``reach`` WINDOWs, less the WINDOW of their own (whose matches share their pixels, so
    agree whatever they measure). 1.0 when there are no clear matches."""
    d = np.asarray(disparity, np.float32)
    sure = (np.asarray(confidence) >= clear) & np.isfinite(d)
    if not sure.any():
        return 1.0
    value = np.where(sure, d, 0).astype(np.float32)

    def sums(img, side):
        return cv2.boxFilter(img, -1, (side, side), normalize=False,
                             borderType=cv2.BORDER_CONSTANT)[sure]

    outer, inner = reach * WINDOW, WINDOW
    count = sums(sure.astype(np.float32), outer) - sums(sure.astype(np.float32), inner)
    local = (sums(value, outer) - sums(value, inner)) / np.maximum(count, 1)
    return float(np.mean((count > 0.5) & (np.abs(d[sure] - local) < tolerance)))


def _tile(pa: np.ndarray, pb: np.ndarray, reach: int, masks=None
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Disparity, confidence and repeat (px, see ``Disparity``) of one tile: the coarse search,
    then Lucas-Kanade; ``masks`` (data of a, of b, float 0/1) weigh every window's sums."""
    # one shift past the bound: a disparity just inside it then has a cost on both sides
    # and its parabola; a minimum at the last shift tried is no minimum (its pixel unknown).
    # At full size: on the views shrunk by two a texture repeating every 5-6 px is at 2.5-3
    # px, near their Nyquist, and 1 px of parallax (0.5 there) lies between whole shifts
    # while the copy a repeat away fits one: sine and checker patterns of 5 px read -4 px for
    # 1 (the copy), those of 6 px were refused as "no texture" (0.00-0.17 % clear)
    d, conf, _, repeat = _search(pa, pb, reach + 1, COARSE_WINDOW, masks)
    # a best whole shift on the bound whose parabola's vertex lies past it: the minimum is
    # outside the search (8 px sines 3.5 px apart, searched to 4: their copy at -4.5 read
    # -3.999 on 10 % of the pixels, confidently), so the pixel is unknown
    conf = np.where(np.abs(d) > reach, np.float32(0), conf)
    return _refine(pa, pb, np.clip(d, -reach, reach), float(reach), masks), conf, repeat


def _search(pa: np.ndarray, pb: np.ndarray, reach: int, side: int = WINDOW, masks=None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Whole-pixel search kept as a running minimum (best cost and its neighbours on both
    sides), parabola through them; confidence 1 - best / mean cost; the mean cost; and where
    the two lowest local minima inside the search all match clearly (fitted cost under
    1 - CLEAR of the mean: a texture that repeats within the search), the least distance
    between them in shifts (else 0).
    The best is taken among the shifts inside +-(reach - 1): the outer two only give the
    parabola its second side, and where one of them is lower the minimum lies past the search
    (confidence 0). Taken over them too, a periodic texture's next copy just past the bound
    won: vertical stripes of 7.3 px, 1 px apart, are 0.5 px apart on the views shrunk by two,
    between whole shifts, while their copy at -3.15 nearly fits the whole shift -3 (cost 0.03
    of the mean against 0.35): every pixel's best was the last shift tried, none was known."""
    shape = pa.shape
    best = np.full(shape, np.inf, np.float32)
    left = np.full(shape, np.inf, np.float32)
    right = np.full(shape, np.inf, np.float32)
    k_best = np.zeros(shape, np.int16)
    total = np.zeros(shape, np.float32)
    # the two lowest local minima, lowest first, and their shifts: of a periodic texture's
    # copies the two lowest need not be neighbours (7.3 px stripes 1 px apart, searched to 8:
    # -6.3 and +7.3 fit whole shifts, +1 lies between them). A copy on the bound itself is
    # inside (noise moves its vertex by hundredths either way: patterns of 5 px, 1 px apart,
    # searched to 4, have their copy at -4); one past it (a repeat's next copy, 8.3 px away
    # when searching to 8) is no second candidate
    low_cost = np.full((2, *shape), np.inf, np.float32)
    low_shift = np.zeros((2, *shape), np.int16)
    none = np.empty((0, 0), np.float32)
    before = previous = none
    shifts = range(-reach, reach + 1)
    for k, s in enumerate(shifts):
        cost = _box((pa - _shift_whole(pb, s)) ** 2, side) if masks is None else \
            _weighted_box((pa - _shift_whole(pb, s)) ** 2,
                          masks[0] * _shift_whole(masks[1], s), side)
        search_step(before, previous, cost, k, 0 < k < len(shifts) - 1, s - 1, reach - 0.75,
                    best, left, right, k_best, total, low_cost, low_shift)
        before, previous = previous, cost
    curv = left - 2 * best + right
    inner = np.isfinite(curv) & (curv > 0) & (left >= best) & (right >= best)
    mean = total / len(shifts)
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(inner, 0.5 * (left - right) / np.where(inner, curv, 1), 0.0)
        conf = np.clip(1.0 - best / mean, 0.0, 1.0)
    d = (k_best - reach + np.clip(frac, -0.5, 0.5)).astype(np.float32)
    conf[~inner] = 0.0
    conf = np.where(np.isfinite(conf), conf, 0.0).astype(np.float32)
    # two minima that both match clearly: a texture repeating within the search, and nothing
    # tells which copy is the parallax. Fitted, not at whole shifts: a copy between two shifts
    # costs more there than one that falls on a shift (the 7.3 px stripes above). Simulated
    # bands (their texture's echo at -d, as low as 0.2 of the mean on one seed: 5-28 % of those
    # pixels wrong by more than 1 px), natural pictures and oriented textures: 0-0.3 % of
    # their clear matches have a second clear minimum; patterns of 5 px, 1 px of parallax,
    # searched to 4: 100 % (sine) or 92 % (checker; its copy 4 px away fits less well)
    clear = np.all(low_cost <= (1 - CLEAR) * mean, axis=0)
    apart = np.abs(low_shift[0] - low_shift[1])
    repeat = np.where(clear & (conf >= CLEAR), apart, 0).astype(np.float32)
    return d, conf, mean, repeat


def _weighted_box(img: np.ndarray, weight: np.ndarray, side: int) -> np.ndarray:
    """Mean of ``img`` over the pixels of ``weight`` 1 in each side x side window."""
    return _box(img * weight, side) / np.maximum(_box(weight, side), 1e-3)


def _refine(pa: np.ndarray, pb: np.ndarray, d: np.ndarray, limit: float, masks=None
            ) -> np.ndarray:
    """Lucas-Kanade steps on d with symmetric warps (A at x - d/2, B at x + d/2); the sums
    over the pixels both warps take from data (``masks``) only."""
    rows, cols = pa.shape
    grid_x = np.ascontiguousarray(np.broadcast_to(np.arange(cols, dtype=np.float32),
                                                  (rows, cols)))
    grid_y = np.ascontiguousarray(np.broadcast_to(np.arange(rows, dtype=np.float32)[:, None],
                                                  (rows, cols)))
    diff = np.array([[-0.5, 0.0, 0.5]], np.float32)
    for k in range(LK_STEPS):
        # the last step fixes the estimate: Lanczos-4 there, whose phase error at fractional
        # shifts is a fraction of cubic's (which left up to 0.08 px on simulated bands)
        how = cv2.INTER_LANCZOS4 if k == LK_STEPS - 1 else cv2.INTER_CUBIC
        wa = _shift_x(pa, -0.5 * d, grid_x, grid_y, how)
        wb = _shift_x(pb, 0.5 * d, grid_x, grid_y, how)
        grad = cv2.filter2D(wa + wb, -1, 0.5 * diff, borderType=cv2.BORDER_REPLICATE)
        # the steps before it over the coarse window: the whole-shift parabola leans towards
        # the whole shift (0.6 px read 0.56-0.58 after one step), and a second step over 15 px
        # doubled the 90th percentile error on natural pictures
        side = WINDOW if k == LK_STEPS - 1 else COARSE_WINDOW
        weight = 1.0 if masks is None else \
            (_shift_x(masks[0], -0.5 * d, grid_x, grid_y, cv2.INTER_NEAREST)
             * _shift_x(masks[1], 0.5 * d, grid_x, grid_y, cv2.INTER_NEAREST))
        num = _box(weight * (wb - wa) * grad, side)
        den = _box(weight * grad * grad, side)
        step = np.where(den > 1e-12, -num / np.maximum(den, 1e-12), 0.0)
        d = np.clip(d + np.clip(step, -0.5, 0.5), -limit, limit).astype(np.float32)
    return d
