"""Measures of two registered views: their correlation over the overlap, and the box of a mask
(the local shifts left between them once placed are measured by :mod:`plenocli.stitch.verify`)."""

from __future__ import annotations

import cv2
import numpy as np

from plenocli.stitch.ncc import ncc
from plenocli.stitch.views import erode


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
