"""Bias (black level) from the sensor's over-scan (optical black) areas.

Like astropy ccdproc's ``subtract_overscan``, but per CFA colour and per row: for each row, the
robust (outlier-clipped) mean of that row's masked pixels of each column phase (with a Bayer
mosaic the row and the column phase together fix the colour). A top over-scan gives
per-column levels the same way.
Inputs are never modified; functions return new arrays.
"""

from __future__ import annotations

import numpy as np

OVERSCAN_MODES = ("auto", "left", "top", "both", "none")


def row_levels(frame: np.ndarray, cols: tuple[int, int], *, period: int = 2,
               smooth_rows: int = 0) -> np.ndarray:
    """Bias of every row, for each column phase, from over-scan columns ``cols``.

    Parameters
    ----------
    frame : ndarray, (rows, cols)
        Raw frame in DN, margins included.
    cols : (start, stop)
        Over-scan columns (half-open), absolute column numbers of ``frame``. The level of a
        row is the mean of its masked pixels of one phase after dropping outliers (beyond 4
        robust sigmas of the row's median).
    period : int
        CFA period: 2 for Bayer (levels per column parity), 1 for mono.
    smooth_rows : int
        Running-mean length, in rows of the same colour (same row parity), applied to the
        per-row medians; 0 or 1 keeps them as they are.

    Returns
    -------
    ndarray, (rows, period)
        ``levels[r, p]`` is the bias (DN) of row ``r`` at columns ``c % period == p``.
    """
    start, stop = cols
    if stop - start < 2 * period:
        raise ValueError(f"over-scan columns {cols} are too few for a CFA period of {period}")
    levels = np.empty((frame.shape[0], period), np.float64)
    for p in range(period):
        first = start + (p - start) % period
        levels[:, p] = _clipped_mean(frame[:, first:stop:period])
    return _smooth(levels, smooth_rows, period, axis=0)


def _clipped_mean(strip: np.ndarray, *, k: float = 4.0) -> np.ndarray:
    """Per-row mean of ``strip`` (rows, n) without outliers beyond ``k`` robust sigmas.

    Robust like a median (hot or dead over-scan pixels are dropped) but without its
    quantisation on integer data and with a smaller variance. Sigma is the MAD of the whole
    strip, which is steadier than a per-row estimate from a few dozen pixels.
    """
    x = strip.astype(np.float64)
    med = np.median(x, axis=1, keepdims=True)
    sigma = 1.4826 * np.median(np.abs(x - med))
    keep = np.abs(x - med) <= max(k * sigma, 0.5)
    count = keep.sum(axis=1)
    # a row whose samples all lie beyond the cut (two that disagree: each is half the gap from
    # their median) keeps its median, not a level of 0 (the whole black left in)
    return np.where(count > 0, np.sum(np.where(keep, x, 0.0), axis=1) / np.maximum(count, 1),
                    med[:, 0])


def column_levels(frame: np.ndarray, rows: tuple[int, int], *, period: int = 2,
                  smooth_cols: int = 0) -> np.ndarray:
    """Bias of every column, for each row phase, from over-scan rows ``rows``.

    Returns ``levels[p, c]``, shape (period, cols): the bias (DN) of column ``c`` at rows
    ``r % period == p``. See :func:`row_levels` for the other parameters.
    """
    return row_levels(frame.T, rows, period=period, smooth_rows=smooth_cols).T


def _smooth(levels: np.ndarray, length: int, period: int, *, axis: int) -> np.ndarray:
    """Running mean over ``length`` samples of one phase; near the ends, a straight-line fit
    over the first (last) ``length`` samples instead of padding, which would bias a drift."""
    if length <= 1:
        return levels
    out = levels.copy()
    for phase in range(period):  # rows of one parity share a colour: smooth each on its own
        sel = [slice(None)] * levels.ndim
        sel[axis] = slice(phase, None, period)
        seq = levels[tuple(sel)]
        window = min(length + (length + 1) % 2, seq.shape[axis] - (seq.shape[axis] + 1) % 2)
        if window >= 3:
            from scipy.signal import savgol_filter  # 0.6 s to import: only when smoothing

            out[tuple(sel)] = savgol_filter(seq, window, 1, axis=axis, mode="interp")
    return out


def subtract_overscan(frame: np.ndarray, *, active_area, masked_areas, overscan: str = "auto",
                      period: int = 2, smooth: int = 0, guard: int = 2,
                      black_level=None) -> tuple[np.ndarray, dict]:
    """Bias-subtract ``frame`` and crop it to its active area.

    Parameters
    ----------
    frame : ndarray, (rows, cols)
        Raw frame (DN) with its margins.
    active_area, masked_areas
        ``[top, left, bottom, right]`` rectangles, as in the frame's metadata.
    overscan : {"auto", "left", "top", "both", "none"}
        Which over-scan to use. ``left``: per-row levels from the masked columns left of the
        active area; ``top``: per-column levels from the masked rows above it; ``both``: per-row
        levels plus the column pattern of the top area (its per-colour median removed); ``none``:
        the constant ``black_level`` per 2 x 2 position. ``auto``: left, else top, else none.
    smooth : int
        Running mean along rows (``left``) or columns (``top``), in pixels of the same colour.
    guard : int
        Pixels dropped at each edge of a masked area (edges of optical black are not dark).
    black_level : sequence of 4 floats
        Per 2 x 2 position black levels, used by ``none``.

    Returns
    -------
    corrected : ndarray float32, (active rows, active cols)
    levels : dict
        ``mode``, and the estimated levels (``row_levels`` per row and phase, ``column_levels``),
        with their mean per colour position.
    """
    mode, left_area, top_area = _choose_areas(frame.shape, active_area, masked_areas,
                                              overscan=overscan, guard=guard, smooth=smooth,
                                              period=period)
    top, left, bottom, right = (int(v) for v in active_area)

    out = frame[top:bottom, left:right].astype(np.float32)
    info: dict = {"mode": mode}
    if mode == "none":
        black = np.asarray(black_level if black_level is not None else [0.0] * 4, np.float64)
        pattern = black.reshape(2, 2) if period == 2 else black[:1].reshape(1, 1)
        rr = (np.arange(top, bottom) % period)[:, None]
        cc = (np.arange(left, right) % period)[None, :]
        out -= pattern[rr, cc].astype(np.float32)
        info["black_level"] = black.tolist()
        return out, info
    if mode in ("left", "both"):
        r0, r1 = left_area[0], left_area[2]
        levels = np.full((frame.shape[0], period), np.nan)
        levels[r0:r1] = row_levels(frame[r0:r1], (left_area[1], left_area[3]), period=period,
                                   smooth_rows=smooth)
        for p in range(period):  # in place, one column phase at a time: no full-size map
            first = (p - left) % period
            out[:, first::period] -= levels[top:bottom, p, None].astype(np.float32)
        info["row_levels"] = levels[top:bottom]
    if mode in ("top", "both"):
        c0, c1 = top_area[1], top_area[3]
        levels_c = np.full((period, frame.shape[1]), np.nan)
        levels_c[:, c0:c1] = column_levels(frame[:, c0:c1], (top_area[0], top_area[2]),
                                           period=period, smooth_cols=smooth)
        if mode == "both":  # only the column pattern: the level comes from the rows
            for p in range(period):
                for q in range(period):
                    levels_c[p, q::period] -= np.nanmedian(levels_c[p, q::period])
        for p in range(period):
            first = (p - top) % period
            out[first::period, :] -= levels_c[p, None, left:right].astype(np.float32)
        info["column_levels"] = levels_c[:, left:right]
    return out, info


def _choose_areas(shape, active_area, masked_areas, *, overscan: str, guard: int, smooth: int,
                  period: int):
    """(mode, left area, top area) after checking every option against the frame: the active
    area inside it, a guard that leaves over-scan pixels, a smoothing no longer than the
    over-scan it smooths."""
    if overscan not in OVERSCAN_MODES:
        raise ValueError(f"overscan must be one of {OVERSCAN_MODES}, got {overscan!r}")
    for name, value in (("guard", guard), ("smooth", smooth)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name} must be a whole number >= 0, got {value!r}")
    top, left, bottom, right = (int(v) for v in active_area)
    if not (0 <= top < bottom <= shape[0] and 0 <= left < right <= shape[1]):
        raise ValueError(f"active_area [{top}, {left}, {bottom}, {right}] is not inside the "
                         f"{shape[1]} x {shape[0]} frame")
    areas = {side: _area_beside(masked_areas, active_area, side=side, guard=guard)
             for side in ("left", "top")}
    bare = {side: _area_beside(masked_areas, active_area, side=side, guard=0)
            for side in ("left", "top")}
    # a left over-scan gives the levels of its own rows only (a top one of its columns):
    # another row's bias is not measured there, so an area that leaves active rows out is no
    # area for this frame (audit 24 W1: rows past it took the last row's level, 14 DN off)
    spans = {"left": (top, bottom, 0, 2, "rows"), "top": (left, right, 1, 3, "columns")}
    short = {side: area for side, area in areas.items() if area and not (
        area[spans[side][2]] <= spans[side][0] and area[spans[side][3]] >= spans[side][1])}
    mode = overscan
    if mode == "auto":
        usable = [side for side in ("left", "top") if areas[side] and side not in short]
        guarded = [side for side in ("left", "top") if bare[side] and side not in short]
        mode = usable[0] if usable else guarded[0] if guarded else "none"
    for side in short:
        if mode in (side, "both"):
            first, stop, lo, hi, what = spans[side]
            other = "top" if side == "left" else "left"
            raise ValueError(f"the {side} over-scan covers {what} {short[side][lo]}-"
                             f"{short[side][hi] - 1} only, but the active area's are {first}-"
                             f"{stop - 1}: the others' bias is not measured; use --overscan "
                             f"{other} or none")
    for side, across in (("left", "columns"), ("top", "rows")):
        if mode in (side, "both") and not areas[side]:
            if bare[side]:
                width = _width(bare[side], side)
                # a level needs 4 (two of each colour) between the guards; bare holds 4
                raise ValueError(f"guard {guard} leaves {max(width - 2 * guard, 0)} of the "
                                 f"{width} {across} of the {side} over-scan, fewer than the 4 "
                                 f"(two of each colour) a level needs; use --guard "
                                 f"{(width - 4) // 2} or less")
            other = "top" if side == "left" else "left"
            where = "left of" if side == "left" else "above"
            raise ValueError(f"no usable over-scan {across} {where} the active area "
                             f"(use --overscan {other} or none)")
    along = {"left": areas["left"] and areas["left"][2] - areas["left"][0],
             "top": areas["top"] and areas["top"][3] - areas["top"][1]}
    span = {"none": shape[0], "left": along["left"], "top": along["top"],
            "both": min(along["left"] or 0, along["top"] or 0)}[mode] // max(period, 1)
    if smooth > max(span, 1):
        raise ValueError(f"smooth {smooth} is longer than the {span} rows or columns of one "
                         f"colour it smooths; use at most {span}")
    return mode, areas["left"], areas["top"]


def _width(area, side: str) -> int:
    return area[3] - area[1] if side == "left" else area[2] - area[0]


def _area_beside(masked_areas, active_area, *, side: str, guard: int):
    """The masked rectangle left of (or above) the active area, shrunk by ``guard``; or None."""
    top, left, bottom, right = (int(v) for v in active_area)
    best = None
    for area in masked_areas or []:
        t, lft, b, r = (int(v) for v in area)
        # the guard only trims across the area: every row of a left area is a row's bias
        if side == "left" and r <= left and b > t:
            cand = (t, lft + guard, b, r - guard)
        elif side == "top" and b <= top and r > lft:
            cand = (t + guard, lft, b - guard, r)
        else:
            continue
        if cand[2] - cand[0] >= 4 and cand[3] - cand[1] >= 4:
            size = (cand[2] - cand[0]) * (cand[3] - cand[1])
            if best is None or size > best[0]:
                best = (size, cand)
    return None if best is None else best[1]
