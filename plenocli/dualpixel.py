"""Dual-pixel views: the right half-pixel image B from the sum S and the left image A, and the
views of a decoded capture (each frame bias-corrected with its own over-scan)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from plenocli.bias import subtract_overscan
from plenocli.model.cfa import period

DUAL_PIXEL_FRAMES = ("S", "A")   # a Canon DPRAW's frame 0 = A + B, frame 1 = A
DUAL_PIXEL_VIEWS = ("A", "B", "S")


@dataclass(frozen=True)
class CaptureViews:
    """Bias-corrected views of one capture's active area.

    ``views`` (V, rows, cols) float32 in DN above black, NaN where derived from a clipped raw
    pixel; ``names`` and ``white_level`` (DN above black is bounded by it) per view;
    ``levels`` the bias levels measured for each input frame (``plenocli.bias``'s dict).
    """

    views: np.ndarray
    names: tuple[str, ...]
    white_level: tuple[float, ...]
    levels: tuple[dict, ...]


def capture_views(frames: np.ndarray, *, names: Sequence[str], active_area, masked_areas,
                  black_level: Sequence, white_level: Sequence[float], cfa: str | None,
                  overscan: str = "auto", smooth: int = 0, guard: int = 2) -> CaptureViews:
    """Bias-correct each frame of a decoded capture (frames, rows, cols) with its own
    over-scan and crop it to ``active_area``; frames named S, A (dual pixel) become views
    A, B = S - A and S (see ``split_views``), other frames stay as they are.

    ``black_level`` (per frame, 4 values) is used with ``overscan="none"``; pixels at or above
    a frame's ``white_level`` are clipped. Raises ValueError naming the frame.
    """
    top, left, bottom, right = active_area
    corrected, levels, clipped = [], [], []
    for k, frame in enumerate(frames):
        try:
            out, info = subtract_overscan(
                frame, active_area=active_area, masked_areas=masked_areas, overscan=overscan,
                period=period(cfa), smooth=smooth, guard=guard, black_level=black_level[k])
        except ValueError as err:
            raise ValueError(f"frame {names[k]}: {err}") from err
        clip = frame[top:bottom, left:right] >= white_level[k]
        np.copyto(out, np.nan, where=clip)
        corrected.append(out)
        clipped.append(clip)
        levels.append(info)
    if tuple(names[:2]) == DUAL_PIXEL_FRAMES:
        views = split_views(corrected[0], corrected[1], sum_clipped=clipped[0],
                            a_clipped=clipped[1])
        # B is bounded by S
        return CaptureViews(views, DUAL_PIXEL_VIEWS,
                            (white_level[1], white_level[0], white_level[0]), tuple(levels))
    return CaptureViews(np.stack(corrected), tuple(names), tuple(white_level), tuple(levels))


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
