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


def overlap_residual(pano_a: np.ndarray, pano_b: np.ndarray, both: np.ndarray) -> float | None:
    """RMS (px) of local shifts left between two warped views (same-size crops of the canvas,
    one channel), over blocks of their overlap ``both``; None when it is too small to measure."""
    from skimage.registration import phase_cross_correlation

    ys, xs = np.nonzero(both)
    if ys.size < 1024:
        return None
    y0, y1, x0, x1 = ys.min() + 2, ys.max() - 1, xs.min() + 2, xs.max() - 1
    if y1 - y0 < 32 or x1 - x0 < 32:
        return None
    ok = both[y0:y1, x0:x1]
    ha = highpass(np.where(ok, pano_a[y0:y1, x0:x1], np.nan))
    hb = highpass(np.where(ok, pano_b[y0:y1, x0:x1], np.nan))
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
