"""The overlaps of neighbour views, measured where both cover the panorama: the exposure gains
(per view, per channel) and the overlap's area (from the maps alone; for a plain homography from
its geometry). Each view is resampled here through the same one map per view as the blend
(:mod:`plenocli.stitch.compose`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from plenocli.progress import step
from plenocli.stitch.compose import Box, coverage, intersect, region_shape, warp_region
from plenocli.stitch.errors import StitchError
from plenocli.stitch.nodata import measured_in
from plenocli.stitch.quality import bounding_box
from plenocli.stitch.registration import difference_row
from plenocli.stitch.views import level
from plenocli.stitch.warp import COVER_EPS_PX, ViewMap, apply_matrix, feather

# An overlap's exposure is measured on up to MEASURE_BLOCKS blocks spread
# along the seam, together at most MEASURE_PIXELS: means settle long before the
# whole overlap of a full-size view (10 Mpx at the 5D Mark IV's size) is resampled a second time
# (gains within 4e-5 of the whole overlap's).
MEASURE_PIXELS = 1 << 20
MEASURE_BLOCKS = 4
MIN_BLOCK_PX = 64
MEASURE_THREADS = 2  # neighbour pairs measured at once (the two cores the stitch is sized for)
# sums over a million pixels hardly see the kernel: bilinear resampling moves the bench's gains
# by under 5e-6 (the 2 x 2 of 1500 px, the pair) at a tenth of Lanczos-4's cost
MEASURE_INTERPOLATION = cv2.INTER_LINEAR


@dataclass(frozen=True)
class Overlap:
    """A neighbour pair's overlap as measured: ``sums`` (2, C), the sums of view a's and view
    b's channels over the ``counts`` (C) pixels of the blocks both views cover and both
    measured in that channel (a channel a view's source estimated, e.g. a Bayer view's rebuilt
    clipped channel, is left out: it is a guess, not the view's light); ``measured`` (2, C),
    the pixels of the ``count`` both cover that each view measured; ``area``, the pixels
    both cover in the whole overlap; and ``products`` (3, C), the sums of a * a, b * b and
    a * b over the ``counts`` pixels (:func:`_check_gain_model`)."""

    sums: np.ndarray
    counts: np.ndarray
    measured: np.ndarray
    count: int
    area: int
    products: np.ndarray


def measure_overlaps(views: Sequence[np.ndarray], maps: list[ViewMap], boxes: list[Box],
                     holes: list, pairs: list[tuple[int, int, str]],
                     estimated: Sequence | None = None) -> list[Overlap | None]:
    """Per neighbour pair: its :class:`Overlap`, or None where the views do not overlap.
    ``estimated``: per view, its estimated channels (see
    :func:`plenocli.stitch.nodata.measured_in`) or None. The pairs are measured in
    MEASURE_THREADS threads (OpenCV's remaps and numpy release the GIL); each pair's figures
    are those of a serial loop."""
    estimated = estimated or [None] * len(views)

    def measure(pair):
        a, b, _ = pair
        region = intersect(boxes[a], boxes[b])
        if region is None:
            return None
        step(f"measuring the overlap of views {a} and {b}")
        n_chan = len(views[a])
        sums, counts, measured, count = (np.zeros((2, n_chan)), np.zeros(n_chan, np.int64),
                                         np.zeros((2, n_chan), np.int64), 0)
        products = np.zeros((3, n_chan))
        for block in _measure_blocks(region, _long_axis(region)):
            crop_a, weight_a = warp_region(views[a], maps[a], block, holes[a],
                                           interpolation=MEASURE_INTERPOLATION)
            crop_b, weight_b = warp_region(views[b], maps[b], block, holes[b],
                                           interpolation=MEASURE_INTERPOLATION)
            both = (weight_a > 0) & (weight_b > 0)
            box = bounding_box(both)
            if box is None:
                continue
            inside = both[box]
            count += int(inside.sum())
            known = [measured_in(estimated[k], maps[k], block, n_chan) for k in (a, b)]
            for c in range(n_chan):
                use = inside
                for k in (0, 1):
                    if known[k][c] is not None:
                        measured[k, c] -= int((inside & ~known[k][c][box]).sum())
                        use = use & known[k][c][box]
                counts[c] += int(use.sum())
                va, vb = (crop[c][box][use].astype(np.float64) for crop in (crop_a, crop_b))
                sums[:, c] += va.sum(), vb.sum()
                products[:, c] += np.dot(va, va), np.dot(vb, vb), np.dot(va, vb)
        area = _covered_by_both(maps[a], maps[b], region, holes[a], holes[b])
        return (Overlap(sums, counts, measured + count, count, area, products) if count
                else None)

    with ThreadPoolExecutor(min(MEASURE_THREADS, len(pairs))) as pool:
        return list(pool.map(measure, pairs))


def _covered_by_both(map_a: ViewMap, map_b: ViewMap, region: Box, holes_a, holes_b) -> int:
    """How many pixels of ``region`` both views cover (their maps only: nothing resampled).
    Views placed by a plain homography (no rig, distortion or no-data pixel) cover a convex
    quadrilateral: each row's run is solved from the geometry and only the pixels within
    SPAN_DOUBT_PX of its ends are mapped, by the maps' own float32 arithmetic (so the count
    is that of the whole maps)."""
    runs = [_row_runs(m, region) if h is None else None
            for m, h in ((map_a, holes_a), (map_b, holes_b))]
    if runs[0] is not None and runs[1] is not None:
        return _count_runs(runs[0], runs[1], (map_a, map_b), region)
    return int(np.count_nonzero(coverage(map_a, region, holes_a)
                                & coverage(map_b, region, holes_b)))


# a pixel whose column lies this close to a run's end, solved in float64, is mapped to decide
# (the maps are float32: 1e-4 px at 2000 px)
SPAN_DOUBT_PX = 0.05


def _row_runs(vmap: ViewMap, region: Box) -> tuple[np.ndarray, ...] | None:
    """Per row of ``region``, the columns [sure_lo, sure_hi] a plain homography's view surely
    covers and [maybe_lo, maybe_hi] it may (panorama columns, clipped to the region); None for
    a map that is not a plain homography, or one whose projective scale changes sign there."""
    if vmap.rig is not None or vmap.k1:
        return None
    m = vmap.to_frame
    ys = np.arange(region[0].start, region[0].stop, dtype=np.float64)
    x_ends = (region[1].start, region[1].stop - 1)
    w_ends = [m[2, 0] * x + m[2, 1] * ys + m[2, 2] for x in x_ends]
    if not all((w > 0).all() for w in w_ends):
        return None
    lower = np.full(ys.shape, -np.inf)
    upper = np.full(ys.shape, np.inf)
    rows, cols = vmap.view_shape
    # source coordinate k (x or y) within [-eps, size - 1 + eps] <=> A u + B >= 0 along a row
    for k, size in ((0, cols), (1, rows)):
        for sign, bound in ((1.0, -COVER_EPS_PX), (-1.0, size - 1 + COVER_EPS_PX)):
            slope = sign * (m[k, 0] - bound * m[2, 0])
            offset = sign * (m[k, 1] * ys + m[k, 2] - bound * (m[2, 1] * ys + m[2, 2]))
            with np.errstate(divide="ignore", invalid="ignore"):
                root = -offset / slope
            if slope > 0:
                lower = np.maximum(lower, root)
            elif slope < 0:
                upper = np.minimum(upper, root)
            else:
                upper = np.where(offset >= 0, upper, -np.inf)
    first, last = x_ends
    clip = lambda v: np.clip(v, first - 1, last + 1)  # noqa: E731
    return (clip(np.ceil(lower + SPAN_DOUBT_PX)), clip(np.floor(upper - SPAN_DOUBT_PX)),
            clip(np.ceil(lower - SPAN_DOUBT_PX)), clip(np.floor(upper + SPAN_DOUBT_PX)))


def _count_runs(runs_a, runs_b, maps, region: Box) -> int:
    """Pixels both views cover, from their :func:`_row_runs`: the rows' sure runs counted, the
    doubtful pixels at their ends mapped."""
    first, last = region[1].start, region[1].stop - 1
    sure_lo = np.maximum(np.maximum(runs_a[0], runs_b[0]), first)
    sure_hi = np.minimum(np.minimum(runs_a[1], runs_b[1]), last)
    maybe_lo = np.maximum(np.maximum(runs_a[2], runs_b[2]), first)
    maybe_hi = np.minimum(np.minimum(runs_a[3], runs_b[3]), last)
    sure = sure_hi >= sure_lo
    count = int(np.maximum(sure_hi - sure_lo + 1, 0).sum())
    # the doubtful columns: the maybe run less the sure one (the whole maybe run where none is)
    spans = [(maybe_lo, np.where(sure, sure_lo - 1, maybe_hi)),
             (np.where(sure, sure_hi + 1, maybe_hi + 1), maybe_hi)]
    ys, xs = [], []
    for lo, hi in spans:
        n = np.maximum(hi - lo + 1, 0).astype(np.int64)
        rows = np.repeat(np.arange(lo.size), n)
        starts = np.repeat(lo.astype(np.int64) - np.cumsum(n) + n, n)
        ys.append(rows + region[0].start)
        xs.append(starts + np.arange(int(n.sum())))
    ys, xs = np.concatenate(ys).astype(np.float64), np.concatenate(xs).astype(np.float64)
    if not ys.size:
        return count
    covered = np.ones(ys.shape, bool)
    for vmap in maps:
        fx, fy = apply_matrix(vmap.to_frame, xs, ys)
        covered &= feather(fx.astype(np.float32), fy.astype(np.float32), vmap.view_shape,
                           None, None) > 0
    return count + int(np.count_nonzero(covered))


def _long_axis(region: Box) -> int:
    rows, cols = region_shape(region)
    return 0 if rows >= cols else 1


def _measure_blocks(region: Box, long_axis: int) -> list[Box]:
    """The blocks of an overlap ``region`` that are measured: MEASURE_BLOCKS segments along its
    long axis (fewer on a seam shorter than MEASURE_BLOCKS * MIN_BLOCK_PX), each whole or, past
    the budget, a window centred in it, as square as the overlap allows (a local shift is
    measured alike along and across)."""
    length, width = region_shape(region)[long_axis], region_shape(region)[1 - long_axis]
    n = max(1, min(MEASURE_BLOCKS, length // MIN_BLOCK_PX))
    budget = MEASURE_PIXELS // n
    across = min(width, max(MIN_BLOCK_PX, math.isqrt(budget)))
    first, middle = region[long_axis].start, (region[1 - long_axis].start
                                              + region[1 - long_axis].stop) // 2
    out = []
    for k in range(n):
        lo, hi = first + k * length // n, first + (k + 1) * length // n
        along = min(hi - lo, max(MIN_BLOCK_PX, budget // across))
        start = (lo + hi - along) // 2
        block = [slice(None), slice(None)]
        block[long_axis] = slice(start, start + along)
        block[1 - long_axis] = slice(middle - across // 2, middle - across // 2 + across)
        out.append(tuple(block))
    return out


def match_gains(overlaps: list, pairs: list[tuple[int, int, str]], stack: np.ndarray
                ) -> np.ndarray:
    """Per-view, per-channel gains from overlap means (log least squares, view 0 fixed) for
    the views ``stack`` (V, C, rows, cols), each channel's from the overlaps where both views
    measured enough of it (:func:`_enough_measured`); refused (StitchError) where that leaves
    a view's channel out of reach of view 0's, where an overlap holds no light in either view,
    or where a view brought to view 0's exposure would fall out of float32's normal range."""
    n_views, n_chan = stack.shape[:2]
    gains = np.ones((n_views, n_chan))
    for c in range(n_chan):
        rows, rhs, used = [], [], []
        for (a, b, _), overlap in zip(pairs, overlaps, strict=True):
            if overlap is None or not _enough_measured(overlap, c):
                continue
            mean_a, mean_b = overlap.sums[:, c] / overlap.counts[c]
            _check_light((mean_a, mean_b), (a, b), c, n_chan)
            _check_gain_model(overlap, (a, b), c, n_chan)
            rows.append(difference_row(a, b, n_views))
            rhs.append(np.log(mean_a / mean_b))
            used.append((a, b))
        _check_reached(used, pairs, overlaps, c, n_chan)
        if rows:
            sol, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
            gains[1:, c] = np.exp(sol)
    _check_scaled_levels(stack, gains)
    return gains


# An overlap's channel is matched from the pixels both views measured in it, when they are at
# least MIN_MEASURED_PX (a 32 x 32 patch: their mean carries 1/32 of a pixel's noise) and
# MIN_MEASURED_SHARE of the pixels both views cover (the gain is the overlap's: a few pixels
# in a corner of it see the views' relative vignetting there). Left out where they are fewer:
# the clipped channel of a highlight that fills the overlap, or a colour lost to unknown
# photosites; a view's channel left with no measured overlap is refused (_check_reached).
MIN_MEASURED_SHARE = 0.1
MIN_MEASURED_PX = 1024


def _enough_measured(overlap: Overlap, channel: int) -> bool:
    return bool(overlap.counts[channel] >= max(MIN_MEASURED_PX,
                                               MIN_MEASURED_SHARE * overlap.count))


def _reached(links: list[tuple[int, int]]) -> set[int]:
    """The views joined to view 0 by ``links`` (pairs of views)."""
    reached, grew = {0}, True
    while grew:
        grew = False
        for a, b in links:
            if (a in reached) != (b in reached):
                reached |= {a, b}
                grew = True
    return reached


def _check_reached(used: list, pairs: list, overlaps: list, channel: int, n_chan: int) -> None:
    """Refuse a channel whose gain some view would get from no measured overlap (it would be
    left at 1 however the views' exposures differ), naming it in its first overlap left out."""
    links = [(a, b) for (a, b, _), o in zip(pairs, overlaps, strict=True) if o is not None]
    lost = _reached(links) - _reached(used)
    for (a, b, _), overlap in zip(pairs, overlaps, strict=True):
        if overlap is None or (a, b) in used or not {a, b} & lost:
            continue
        k = int(np.argmin(overlap.measured[:, channel]))
        view, other = (a, b)[k], (a, b)[1 - k]
        share = overlap.measured[k, channel] / overlap.count
        share = f"only {100 * share:.2g} %" if share else "none"
        colour = ("red", "green", "blue")[channel] if n_chan == 3 else f"channel {channel}"
        raise StitchError(
            f"view {view}'s {colour} is measured in {share} of its overlap "
            f"with view {other} (the rest rebuilt from the colour around clipped or unknown "
            f"photosites): too little to match its {colour} exposure; stitch without exposure "
            "matching (--gains none), or views with fewer clipped photosites there")


def _check_scaled_levels(stack: np.ndarray, gains: np.ndarray) -> None:
    """A view at view 0's exposure is written in float32: a level below its normal range is
    stored with fewer bits and its darker pixels as 0 (view 0 at 1e-38 took a view 1e-77 times
    as bright to zeros). Past its largest value, the written result is refused as any is."""
    tiny = float(np.finfo(np.float32).tiny)
    for k, view in enumerate(stack):
        for c, channel in enumerate(view):
            scaled = level(channel) * gains[k, c]
            if 0 < scaled < tiny:
                who = "view 0" if k == 0 else f"view {k} brought to view 0's exposure"
                raise StitchError(
                    f"{who} has a level of {scaled:.3g}, below float32's normal range "
                    f"({tiny:.3g}): its pixels would be stored with fewer bits or as 0; scale "
                    "the views (all by one factor) nearer 1, or stitch without exposure "
                    "matching (--gains none)")


# An exposure gain explains an overlap when view b is view a times a factor. Then the residual
# of b = k a (k the ratio of the means) is within sqrt(2) of the best line's, b = alpha a +
# beta, whatever the noise or misregistration (errors alike in both views: the line's gain
# from fitting their noise is at most that). An offset left in one view (a black level not
# subtracted) leaves the gain's residual many times the line's, and moves k by offset / mean
# (audit 24 W1: views of one exposure, 0.3 of the level apart, got gains 1 and 3.07; the
# residuals were 0.193 and 0.028, and 0.0282 and 0.0281 for the right pair).
OFFSET_RESIDUAL_RATIO = 2.0
OFFSET_SLOPE_SHARE = 0.02  # the line's slope this far from k at least: a gain error that shows


def _check_gain_model(overlap: Overlap, pair: tuple[int, int], channel: int,
                      n_chan: int) -> None:
    """Refuse (StitchError) a pair whose overlap a gain does not explain but a gain and an
    offset do: the views differ by an offset (see OFFSET_RESIDUAL_RATIO)."""
    n = overlap.counts[channel]
    mean_a, mean_b = overlap.sums[:, channel] / n
    aa, bb, ab = overlap.products[:, channel] / n
    var_a, cov = aa - mean_a * mean_a, ab - mean_a * mean_b
    if not var_a > 1e-12 * aa:
        return   # a flat overlap: an offset cannot be told from a gain there
    k = mean_b / mean_a
    slope = cov / var_a
    gain_residual = max(bb - 2 * k * ab + k * k * aa, 0.0)
    line_residual = max(bb - mean_b * mean_b - cov * slope, 0.0)
    if (gain_residual <= OFFSET_RESIDUAL_RATIO ** 2 * line_residual + 1e-12 * bb
            or abs(slope / k - 1) <= OFFSET_SLOPE_SHARE):
        return
    a, b = pair
    where = f" (channel {channel})" if n_chan > 1 else ""
    offset = float(mean_b - slope * mean_a)
    raise StitchError(
        f"views {a} and {b} differ by an offset, not by an exposure gain, in their overlap"
        f"{where}: view {b} = {slope:.4g} x view {a} {'-' if offset < 0 else '+'} "
        f"{abs(offset):.4g} leaves {np.sqrt(line_residual / gain_residual):.2g} of the "
        "residual a gain leaves; subtract the views' black level, or stitch without exposure "
        "matching (--gains none)")


def _check_light(means, pair: tuple[int, int], channel: int, n_chan: int) -> None:
    """Refuse a pair whose overlap averages zero or less in either view: an exposure gain is a
    ratio of light, and there is none to take it from (zero is not black: an offset left in).
    Noise about a black of 0 (a dark, bias-subtracted scene) leaves the mean above zero; an
    offset that does too cannot be told from the scene by the pixels alone (resampled views,
    refocused or stitched, ring below zero at every edge of a black area) and biases the
    gains: --gains none keeps the views as recorded."""
    for k, view in enumerate(pair):
        if means[k] > 0:
            continue
        where = f" (channel {channel})" if n_chan > 1 else ""
        raise StitchError(
            f"view {view}'s overlap with view {pair[1 - k]} averages {means[k]:.4g}{where}: "
            "zero is not black there (an offset left in), so no exposure gain can be "
            "measured: subtract the black level (plenocli bias), or stitch without exposure "
            "matching (--gains none)")
