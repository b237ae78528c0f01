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


def highlight_split(white_a: np.ndarray, white_s: np.ndarray, *, cfa: str | None,
                    degree: int = 4) -> np.ndarray:
    """The per-pixel A/S split of a dual-pixel sensor, measured on a white image.

    The split varies smoothly across the frame (left-right fall-off of the half-pixels) and with
    colour, so each CFA colour plane gets a 2-D polynomial of ``degree`` in the normalised pixel
    coordinates, fitted by least squares to A = split * S (photon noise averages out over the
    whole plane, and the frame's edges are not biased as a moving average would be).

    Parameters
    ----------
    white_a, white_s : ndarray, (rows, cols)
        A and S of a white image, processed like the capture (DN above black, or flat-fielded
        with the same gains); NaN pixels are left out.
    cfa : 2 x 2 pattern of the frames, or None for a monochrome sensor.
    degree : polynomial degree (total) of the split over the frame.

    Returns
    -------
    ndarray float32, (rows, cols): A / S.
    """
    if white_a.shape != white_s.shape:
        raise ValueError(f"white A and S differ in shape: {white_a.shape} vs {white_s.shape}")
    if not 0 <= degree <= 8:
        raise ValueError(f"degree must be between 0 and 8, got {degree}")
    rows, cols = white_a.shape
    split = np.empty(white_a.shape, np.float32)
    step = 2 if cfa else 1
    powers = [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]
    for r in range(step):
        for c in range(step):
            yy, xx = np.mgrid[r:rows:step, c:cols:step]
            x, y = 2.0 * xx / max(cols - 1, 1) - 1.0, 2.0 * yy / max(rows - 1, 1) - 1.0
            basis = np.stack([x**i * y**j for i, j in powers], axis=-1)
            a = np.asarray(white_a[r::step, c::step], np.float64)
            s = np.asarray(white_s[r::step, c::step], np.float64)
            valid = np.isfinite(a) & np.isfinite(s) & (s > 0)
            if valid.sum() < 4 * len(powers):
                raise ValueError("the white image has too few valid pixels to measure the A/S "
                                 "split")
            design = basis[valid] * s[valid, np.newaxis]
            coef, *_ = np.linalg.lstsq(design, a[valid], rcond=None)
            split[r::step, c::step] = basis @ coef
    if not np.all((split > 0) & (split < 1)):
        raise ValueError("the A/S split measured on the white image leaves (0, 1); is it a "
                         "dual-pixel white with views A and S?")
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
