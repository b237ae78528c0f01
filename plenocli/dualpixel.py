"""Dual-pixel views: the right half-pixel image B from the sum S and the left image A."""

from __future__ import annotations

import numpy as np


def split_views(sum_frame: np.ndarray, a_frame: np.ndarray, *, sum_clipped: np.ndarray,
                a_clipped: np.ndarray) -> np.ndarray:
    """Views A, B, S from bias-corrected frames, with B = S - A.

    Parameters
    ----------
    sum_frame, a_frame : ndarray, (rows, cols), DN above black
        Bias-corrected frame 0 (S = A + B) and frame 1 (A).
    sum_clipped, a_clipped : ndarray of bool, (rows, cols)
        Pixels whose raw value reached the white level.

    Returns
    -------
    ndarray float32, (3, rows, cols)
        A, B and S. Values derived from a clipped raw pixel are NaN: where S is clipped, S and B;
        where A is clipped, A and B (B = S - A would be silently wrong there).
    """
    if sum_frame.shape != a_frame.shape:
        raise ValueError(f"S and A differ in shape: {sum_frame.shape} vs {a_frame.shape}")
    views = np.empty((3, *sum_frame.shape), np.float32)
    np.subtract(sum_frame, a_frame, out=views[1], dtype=np.float32)
    np.copyto(views[0], a_frame)
    np.copyto(views[2], sum_frame)
    # copyto with a mask writes in one pass (boolean-index assignment gathers indices first)
    np.copyto(views[0], np.nan, where=a_clipped)
    np.copyto(views[2], np.nan, where=sum_clipped)
    np.copyto(views[1], np.nan, where=sum_clipped)
    np.copyto(views[1], np.nan, where=a_clipped)
    return views
