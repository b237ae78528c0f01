"""Coarse to fine registration of a prism rig's views: where to look at full resolution.

The rig predicts each pair's shift only to within a few per cent of the canvas (its focal length,
prism and object distance are nominal), so the full-resolution search used to undistort and
correlate strips twice that tolerance wide, over the whole canvas height: at the 5D Mark IV's
size two 17 Mpx strips per pair. Here each pair is first registered on the luminance reduced
``factor`` times (area mean) through the same rig scaled to the reduced views, which finds the
shift to about a reduced pixel. The full-resolution registration then searches only
a few reduced pixels around it, on strips holding the overlap and, across it, the
``FINE_PIXELS`` whose texture the two views share most (a translation has two parameters;
half a million textured pixels fix them far below the 0.01 px the stitch promises).

Nothing here decides a result: the reduced pass only chooses the window, and a pair it cannot
register (no texture at the reduced scale, an ambiguous match) is searched at full resolution
over the rig's whole tolerance as before, so the refusals stay those of the full search.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from plenocli.stitch.errors import StitchError
from plenocli.stitch.rig import STRIP_MARGIN_PX, PrismRig, canvases, rig_strips
from plenocli.stitch.translation import (
    RUNNER_UP_EXCLUSION_PX,
    estimate_translation,
    shifted_overlap,
)
from plenocli.stitch.views import highpass, neighbour_pairs

FINE_PIXELS = 1 << 19  # per strip at full resolution
MIN_REDUCED_PX = 256  # the reduced views' short side: enough texture for the reduced search


def reduction(shape: tuple[int, int]) -> int:
    """The reduction of the coarse pass for views of ``shape``: 4 or 2 while the reduced views
    keep MIN_REDUCED_PX on their short side, else 1 (no coarse pass)."""
    for factor in (4, 2):
        if min(shape) >= MIN_REDUCED_PX * factor:
            return factor
    return 1


def fine_tolerance(factor: int) -> float:
    """How far (px) around the reduced pass's shift the full resolution searches. The reduced
    search is right to about a reduced pixel, but it cannot see a runner-up within
    RUNNER_UP_EXCLUSION_PX reduced pixels of its match (``factor`` times that at full
    resolution): the window reaches past that, so a periodic scene whose period lies there is
    still refused as ambiguous by the full-resolution search, as without the reduced pass."""
    return float((RUNNER_UP_EXCLUSION_PX + 2) * factor)


def reduced(luma: np.ndarray, rig: PrismRig, factor: int) -> tuple[np.ndarray, PrismRig]:
    """The luminance (V, rows, cols) reduced ``factor`` times by area means (NaN where any
    pixel of a cell has none), cropped to whole cells, and the rig of views of that size: the
    sensor width scaled with the crop, so a reduced pixel is exactly ``factor`` pixels."""
    rows, cols = (s // factor * factor for s in luma.shape[1:])
    size = (cols // factor, rows // factor)
    small = np.stack([cv2.resize(np.ascontiguousarray(v[:rows, :cols], np.float32), size,
                                 interpolation=cv2.INTER_AREA) for v in luma])
    return small, dataclasses.replace(rig, sensor_mm=rig.sensor_mm * cols / luma.shape[2])


def fine_windows(luma: np.ndarray, rig: PrismRig, origins: np.ndarray, layout: str,
                 expected: dict, search: dict) -> tuple[dict, dict]:
    """Per neighbour pair, the (prior, tolerance) of the full-resolution search and the canvas
    rows (columns for "v") of view a it reads, or None for all of them: the rig's prediction
    moved by what the reduced pass measured, within :func:`fine_tolerance`; the rig's own
    (prior, tolerance) and None where the reduced pass finds nothing or the views are small."""
    factor = reduction(luma.shape[1:])
    windows, across = dict(expected), dict.fromkeys(expected)
    if factor == 1:
        return windows, across
    small, small_rig = reduced(luma, rig, factor)
    small_origins, small_size = canvases(small_rig, small.shape[1:])
    for a, b, direction in neighbour_pairs(layout):
        prior, tol = expected[(a, b)]
        small_prior = small_origins[b] - small_origins[a]
        img_a, img_b, off_a, off_b = rig_strips(small, small_rig, small_origins, small_size, a, b,
                                                direction, (small_prior, tol / factor))
        to_crops = np.subtract(off_b, off_a)
        try:
            dy, dx, _ = estimate_translation(img_a, img_b, direction=direction,
                                             prior=tuple(small_prior + to_crops),
                                             tolerance_px=tol / factor, **search)
        except StitchError:
            continue  # searched at full resolution over the whole tolerance
        moved = np.array([dy, dx]) - to_crops - small_prior
        windows[(a, b)] = (tuple(float(v) for v in np.asarray(prior) + factor * moved),
                           fine_tolerance(factor))
        span = _textured_span(img_a, img_b, (dy, dx), direction, factor)
        if span is not None:  # reduced canvas -> common -> full-resolution canvas of view a
            k = 0 if direction == "h" else 1
            first = (span[0] + off_a[k] + small_origins[a, k]) * factor - origins[a, k]
            across[(a, b)] = (int(first) - STRIP_MARGIN_PX,
                              int(first + (span[1] - span[0]) * factor) + STRIP_MARGIN_PX)
    return windows, across


def _textured_span(img_a: np.ndarray, img_b: np.ndarray, shift: tuple[float, float],
                   direction: str, factor: int) -> tuple[int, int] | None:
    """The rows (columns for "v") of the reduced strip of a, whose full-resolution strips hold
    about FINE_PIXELS, where the two aligned views share the most texture; None when the whole
    overlap is within that budget."""
    crops = shifted_overlap(img_a, img_b, int(round(shift[0])), int(round(shift[1])))
    if crops is None:
        return None
    crop_a, crop_b, origin = crops
    if direction == "v":
        crop_a, crop_b, origin = crop_a.T, crop_b.T, origin[::-1]
    length = int(FINE_PIXELS // (crop_a.shape[1] * factor * factor))
    if length >= crop_a.shape[0]:
        return None
    shared = np.sum(np.maximum(highpass(crop_a) * highpass(crop_b), 0), axis=1)
    window = np.convolve(shared, np.ones(length), mode="valid")
    first = int(np.argmax(window))
    return origin[0] + first, origin[0] + first + length
