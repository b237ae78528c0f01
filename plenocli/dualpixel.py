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


def highlight_split(white_a: np.ndarray, white_s: np.ndarray, *, cfa: str | None,
                    size: int = 15) -> np.ndarray:
    """The per-pixel A/S split of a dual-pixel sensor, measured on a white image.

    The split varies slowly across the frame (left-right fall-off of the half-pixels) and with
    colour, so it is averaged over ``size`` x ``size`` pixels of the same CFA colour (a box mean
    of A divided by a box mean of S: photon noise averages out, a linear trend is kept).

    Parameters
    ----------
    white_a, white_s : ndarray, (rows, cols)
        A and S of a white image, processed like the capture (DN above black, or flat-fielded
        with the same gains); NaN pixels are left out.
    cfa : 2 x 2 pattern of the frames, or None for a monochrome sensor.
    size : odd box size in pixels of one colour plane.

    Returns
    -------
    ndarray float32, (rows, cols): A / S, NaN where the white gives no estimate.
    """
    import cv2

    if white_a.shape != white_s.shape:
        raise ValueError(f"white A and S differ in shape: {white_a.shape} vs {white_s.shape}")
    if size < 1 or size % 2 == 0:
        raise ValueError(f"size must be a positive odd number of pixels, got {size}")
    split = np.full(white_a.shape, np.nan, np.float32)
    step = 2 if cfa else 1
    for r in range(step):
        for c in range(step):
            a = np.asarray(white_a[r::step, c::step], np.float32)
            s = np.asarray(white_s[r::step, c::step], np.float32)
            valid = np.isfinite(a) & np.isfinite(s)
            box = {"ksize": (size, size), "normalize": False, "borderType": cv2.BORDER_REFLECT}
            sum_a = cv2.boxFilter(np.where(valid, a, 0).astype(np.float32), -1, **box)
            sum_s = cv2.boxFilter(np.where(valid, s, 0).astype(np.float32), -1, **box)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = sum_a / sum_s
            ratio[~((sum_s > 0) & (ratio > 0) & (ratio < 1))] = np.nan
            split[r::step, c::step] = ratio
    return split


def recover_highlights(a_view: np.ndarray, s_view: np.ndarray, split: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Rebuild the sum S where it clipped but the half-pixel A did not: S = A / split.

    Parameters
    ----------
    a_view, s_view : ndarray, (rows, cols)
        A and S views (NaN where clipped), e.g. from :func:`split_views`.
    split : ndarray, (rows, cols)
        A / S measured on a white image (:func:`highlight_split`).

    Returns
    -------
    views : ndarray float32, (3, rows, cols)
        A, B = S - A, and S, with S and B rebuilt where S was NaN and A and the split are finite;
        NaN stays where A clipped as well.
    rebuilt : ndarray of bool, (rows, cols)
        The pixels whose S (and B) were rebuilt.

    Limits: the split is the white image's; where the scene's light reaches the pupil unlike a
    uniform white (defocused edges, strong parallax) A / S differs and the rebuilt S is off by the
    same factor.
    """
    if not (a_view.shape == s_view.shape == split.shape):
        raise ValueError(f"A, S and split differ in shape: {a_view.shape}, {s_view.shape}, "
                         f"{split.shape}")
    s = np.asarray(s_view, np.float32).copy()
    a = np.asarray(a_view, np.float32)
    rebuilt = ~np.isfinite(s) & np.isfinite(a) & np.isfinite(split)
    s[rebuilt] = a[rebuilt] / split[rebuilt]
    views = np.empty((3, *s.shape), np.float32)
    views[0] = a
    np.subtract(s, a, out=views[1])
    views[2] = s
    return views, rebuilt
