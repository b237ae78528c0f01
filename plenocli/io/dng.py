"""Writing raw DNG files (for synthetic captures): one raw IFD per frame, masked areas kept.

The files follow DNG 1.4: CFA (or mono LinearRaw-free BlackIsZero) IFDs with BlackLevel,
WhiteLevel, ActiveArea and MaskedAreas; each frame's name goes into its ImageDescription, which
``plenocli decode`` reads back. LibRaw opens the first frame; plenocli reads every frame.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import tifffile

from plenocli.io.atomic import atomic_path
from plenocli.model.cfa import shift_pattern

CFA_CODES = {"R": 0, "G": 1, "B": 2}


def write_dng(path: str | os.PathLike, frames: np.ndarray, *, cfa: str | None,
              black_levels: Sequence[float], white_level: int,
              active_area: Sequence[int], masked_areas: Sequence[Sequence[int]] = (),
              frame_names: Sequence[str] | None = None,
              model: str = "plenocli synthetic",
              as_shot_neutral: Sequence[float] | None = None,
              color_matrix: Sequence[float] | None = None) -> None:
    """Write uint16 ``frames`` (frames, rows, cols) as a multi-frame DNG, atomically.

    ``cfa`` is the Bayer pattern at the frames' pixel (0, 0); it is written, as DNG defines
    CFAPattern, for the ActiveArea's top-left pixel (the two differ where the active area
    starts on an odd row or column).
    ``black_levels`` is one level per frame (DN), written as the DNG BlackLevel tag; the real
    per-row bias lives in the pixel data and its masked areas. ``active_area`` and each masked
    area are ``[top, left, bottom, right]``. ``as_shot_neutral`` (camera R, G, B of white) and
    ``color_matrix`` (9 values, XYZ -> camera, row-major, written as ColorMatrix1 for D65) are
    the colour tags of DNG 1.4.
    """
    data = np.asarray(frames)
    if data.ndim == 2:
        data = data[np.newaxis]
    if data.dtype != np.uint16:
        raise ValueError(f"DNG frames must be uint16, got {data.dtype}")
    names = list(frame_names) if frame_names else [f"frame{k}" for k in range(len(data))]
    masked_flat = [int(v) for area in masked_areas for v in area]
    at_active = shift_pattern(cfa, int(active_area[0]), int(active_area[1]))
    with atomic_path(path) as tmp:
        with tifffile.TiffWriter(tmp) as tw:
            for k, frame in enumerate(data):
                tags = [
                    (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
                    (50707, "B", 4, (1, 4, 0, 0), True),  # DNGBackwardVersion
                    (50708, "s", 0, model, True),  # UniqueCameraModel
                    (50714, "d", 1, (float(black_levels[k]),), True),  # BlackLevel
                    (50717, "I", 1, (int(white_level),), True),  # WhiteLevel
                    (50829, "I", 4, tuple(int(v) for v in active_area), True),  # ActiveArea
                ]
                if masked_flat:
                    tags.append((50830, "I", len(masked_flat), tuple(masked_flat), True))
                if as_shot_neutral is not None:
                    tags.append((50728, "2I", 3, _rational(as_shot_neutral), True))
                if color_matrix is not None:
                    tags += [(50721, "2i", 9, _rational(color_matrix), True),
                             (50778, "H", 1, (21,), True)]  # CalibrationIlluminant1 = D65
                if cfa:
                    tags += [(33421, "H", 2, (2, 2), True),  # CFARepeatPatternDim
                             (33422, "B", 4, tuple(CFA_CODES[c] for c in at_active), True)]
                tw.write(np.ascontiguousarray(frame), photometric=32803 if cfa else "minisblack",
                         compression=None, subfiletype=0, description=names[k], metadata=None,
                         extratags=tags)


def _rational(values: Sequence[float], denominator: int = 1_000_000) -> tuple[int, ...]:
    """(S)RATIONAL tag values: numerator, denominator pairs."""
    return tuple(v for x in values for v in (int(round(float(x) * denominator)), denominator))
