"""Measures of how well two registered views agree: the correlation over their overlap, and the
local shifts left between them once warped onto the panorama."""

from __future__ import annotations

import cv2
import numpy as np

from plenocli.stitch.ncc import ncc
from plenocli.stitch.views import erode, highpass


def aligned_correlation(ha: np.ndarray, hb: np.ndarray, h_ab: np.ndarray,
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
    cover = erode(cover, 2)
    if cover.sum() < 64:
        return float("nan")
    return ncc(ha[cover], warped[cover])


def bounding_box(mask: np.ndarray) -> tuple[slice, slice] | None:
    """Smallest (row slice, column slice) holding every True pixel, or None."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def _longest_run(flags: np.ndarray) -> tuple[int, int] | None:
    """[start, stop) of the longest run of True in a 1-D boolean array, or None."""
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    if edges.size == 0:
        return None
    starts, stops = edges[::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    return int(starts[k]), int(stops[k])


def overlap_residual(pieces: list, long_axis: int) -> float | None:
    """RMS (px) of the local shifts left between two warped views over the blocks of their
    overlap: ``pieces`` (view a, view b, pixels both cover), same-size crops of the canvas, one
    channel, in order along a seam whose long axis is ``long_axis``; None when too little of it
    is covered to measure."""
    from skimage.registration import phase_cross_correlation

    if sum(int(both.sum()) for _, _, both in pieces) < 1024:
        return None
    shifts = []
    for pano_a, pano_b, both in pieces:
        if min(both.shape) < 32:
            continue
        # an overlap that is not a rectangle (homography, undistorted views): keep the longest
        # run of lines across the block that lie wholly inside it
        run = _longest_run(both.all(axis=long_axis))
        if run is None or run[1] - run[0] < 16:
            continue
        across = [slice(None), slice(None)]
        across[1 - long_axis] = slice(*run)
        # both views cover every pixel of the run: high-passed alike, with no no-data to mask
        ha, hb = (highpass(x[tuple(across)]) for x in (pano_a, pano_b))
        if ha.std() == 0:
            continue
        shift, _, _ = phase_cross_correlation(ha, hb, upsample_factor=20)
        shifts.append(shift)
    if not shifts:
        return None
    return float(np.sqrt(np.mean(np.sum(np.square(shifts), axis=1))))
