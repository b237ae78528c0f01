"""Vignetting correction from a white image (paper sections 5.2 and 6).

The white image is median filtered, normalised by its maximum (or a high percentile, more robust
to hot pixels) and inverted into a per-pixel gain. With a Bayer mosaic each colour plane is
filtered and normalised on its own, so the gain also balances the colours of the white target.
Where the white image is darker than ``floor`` times the reference, the gain is NaN (masked)
rather than a huge factor that would multiply noise.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import median_filter

from plenocli.model.cfa import positions

REFERENCES = ("max", "percentile")


def white_gain(white: np.ndarray, *, cfa: str | None = None, median_px: int = 5,
               reference: str = "max", percentile: float = 99.5,
               floor: float = 0.05) -> np.ndarray:
    """Per-pixel gain that flattens ``white``.

    Parameters
    ----------
    white : ndarray, (rows, cols)
        Bias-corrected white image (DN); NaN pixels (clipped) are ignored.
    cfa : str or None
        2 x 2 Bayer pattern at pixel (0, 0); each colour plane is handled separately.
    median_px : int
        Median filter size in pixels of one colour plane (odd; 1 disables it).
    reference : {"max", "percentile"}
        Normalise by the maximum of the filtered plane (the paper) or by a percentile.
    percentile : float
        The percentile used with ``reference="percentile"``.
    floor : float
        Pixels whose filtered white is below ``floor * reference`` get a NaN gain.

    Returns
    -------
    ndarray float32, (rows, cols)
        ``gain = reference / median_filtered(white)``, >= 1 where defined.
    """
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    if median_px < 1 or median_px % 2 == 0:
        raise ValueError(f"median_px must be a positive odd number, got {median_px}")
    if not 0 <= floor < 1:
        raise ValueError(f"floor must be in [0, 1), got {floor}")
    if not 0 <= percentile <= 100:  # also refuses NaN
        raise ValueError(f"percentile must be in [0, 100], got {percentile}")
    step = 2 if cfa else 1
    if white.ndim != 2:
        raise ValueError(f"white must be 2-D (rows, cols), got shape {white.shape}")
    plane_side = min(white.shape) // step
    if plane_side == 0:  # no median window fits, not even 1 px: say what the image lacks
        raise ValueError(f"a {white.shape[0]} x {white.shape[1]} px image is narrower than "
                         f"one 2 x 2 cell of its {cfa} pattern: some colour has no pixel to "
                         "flat-field; give a frame of at least 2 x 2 px")
    if median_px > plane_side:  # before any filter allocates its windows
        largest = max(plane_side - 1 + plane_side % 2, 1)
        pixels = f"{plane_side} pixel{'s' * (plane_side > 1)}"
        raise ValueError(f"the median window of {median_px} px is larger than the image "
                         f"({pixels} of one colour across); use at most {largest}")
    gain = np.full(white.shape, np.nan, np.float32)
    for r, c in positions(cfa):
        plane = np.asarray(white[r::step, c::step], np.float32)
        if not np.isfinite(plane).any():
            raise ValueError("the white image has no valid pixel (all NaN: clipped or masked)")
        smooth = _median(plane, median_px)
        finite = smooth[np.isfinite(smooth)]
        if finite.size == 0:
            raise ValueError("the white image has no valid pixel")
        ref = finite.max() if reference == "max" else np.percentile(finite, percentile)
        if not ref > 0:
            raise ValueError("the white image is not brighter than its black level")
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(smooth >= floor * ref, ref / smooth, np.nan)
        gain[r::step, c::step] = g
    return gain


def _median(plane: np.ndarray, size: int) -> np.ndarray:
    bad = ~np.isfinite(plane)
    if bad.any():  # median filters do not skip NaN: fill, filter, re-mark
        plane = np.where(bad, np.nanmedian(plane), plane).astype(np.float32)
    if size == 1:
        out = plane.copy()
    elif size in (3, 5):
        out = cv2.medianBlur(np.ascontiguousarray(plane), size)  # float32 fast path
    else:
        out = median_filter(plane, size=size, mode="nearest")
    _symmetric_borders(plane, out, size // 2)
    out[bad] = np.nan
    return out


def _symmetric_borders(plane: np.ndarray, out: np.ndarray, half: int) -> None:
    """Redo the border band with windows shrunk to stay centred on their pixel.

    A padded window at the edge is lopsided, and on a vignetting ramp its median is biased by
    up to a few percent; a centred window (smaller near the edge) keeps a linear ramp exact.
    """
    rows, cols = plane.shape
    if half == 0 or rows <= 2 * half or cols <= 2 * half:
        return
    col_limit = np.minimum(np.minimum(np.arange(cols), cols - 1 - np.arange(cols)), half)
    row_limit = np.minimum(np.minimum(np.arange(rows), rows - 1 - np.arange(rows)), half)
    for r in [*range(half), *range(rows - half, rows)]:  # top and bottom rows, all columns
        hr = int(row_limit[r])
        slab = plane[r - hr:r + hr + 1]
        for hc in range(half + 1):
            sel = col_limit == hc
            out[r, sel] = median_filter(slab, size=(2 * hr + 1, 2 * hc + 1),
                                        mode="nearest")[hr, sel]
    for c in [*range(half), *range(cols - half, cols)]:  # left and right columns, inner rows
        hc = int(col_limit[c])
        slab = plane[:, c - hc:c + hc + 1]
        inner = slice(half, rows - half)
        out[inner, c] = median_filter(slab, size=(2 * half + 1, 2 * hc + 1),
                                      mode="nearest")[inner, hc]


def white_gains(whites: np.ndarray, *, names=None, cfa: str | None = None,
                **options) -> np.ndarray:
    """``white_gain`` of each view of ``whites`` (views, rows, cols): each view (A and B of a
    dual-pixel sensor) has its own fall-off. ``options`` as for ``white_gain``; a ValueError
    names the view (by ``names[k]``, else its index)."""
    gains = np.empty(whites.shape, np.float32)
    for k, plane in enumerate(whites):
        try:
            gains[k] = white_gain(plane, cfa=cfa, **options)
        except ValueError as err:
            raise ValueError(f"view {names[k] if names else k}: {err}") from err
    return gains


def check_gains(gains: np.ndarray, *, cfa: str | None, reference: str, floor: float,
                names=None) -> None:
    """ValueError unless ``gains`` (views, rows, cols) is what ``white_gains`` makes with these
    options: NaN (masked) or finite gains in (0, 1 / floor], and per view and colour plane a
    gain of exactly 1 where the white was brightest (``reference="max"``) or gains on both
    sides of 1 (``"percentile"``). A gain file edited, scaled or made for other options would
    otherwise change every corrected pixel."""
    if reference not in REFERENCES or not 0 <= floor < 1:
        raise ValueError(f"the gain was made with reference {reference!r} and floor {floor!r}, "
                         "which flat does not make")
    step = 2 if cfa else 1
    top = np.float32(1 / floor) if floor else np.inf
    for k, view in enumerate(np.asarray(gains)):
        name = names[k] if names is not None and k < len(names) else k
        for r, c in positions(cfa):
            plane = view[r::step, c::step]
            finite = plane[np.isfinite(plane)]
            if finite.size == 0:
                raise ValueError(f"view {name}: the gain has no valid pixel")
            low, high = float(finite.min()), float(finite.max())
            if low <= 0 or high > top * (1 + 1e-6):
                raise ValueError(f"view {name}: gains from {low:.4g} to {high:.4g}, outside "
                                 f"(0, {float(top):.4g}] that floor {floor:g} allows")
            if (abs(low - 1) > 1e-5 if reference == "max" else not low <= 1 <= high):
                raise ValueError(f"view {name}: the smallest gain is {low:.6g}, not 1 as "
                                 f"reference {reference} gives (where the white is "
                                 "brightest): the gain was scaled or edited")


def apply_gain(frame: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """``frame * gain`` as float32 (any shape, e.g. a stack of views and their gains); NaN
    where the gain is masked."""
    if frame.shape != gain.shape:
        raise ValueError(f"frame {frame.shape} and gain {gain.shape} differ in shape")
    return np.multiply(frame, gain, dtype=np.float32)
