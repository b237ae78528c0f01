"""A camera's Orientation (EXIF / TIFF / DNG tag 274): how its stored image turns upright.

The pipeline keeps the sensor's order (grids, crops, over-scan and CFA phase are all in sensor
coordinates); decode records the value, every stage carries it, and only ``develop`` turns its
photograph upright, as LibRaw does, so that the pixels stand upright in every reader (many,
tifffile and OpenCV among them, ignore the tag in a TIFF or PNG).
"""

from __future__ import annotations

import numpy as np

TAG = 274
# what the stored image needs to stand upright, per value (TIFF 6.0, EXIF 2.3)
TURNS = {1: "upright as stored", 2: "mirrored left-right", 3: "rotated 180 degrees",
         4: "mirrored top-bottom", 5: "transposed (mirrored about the main diagonal)",
         6: "rotated 90 degrees clockwise", 7: "mirrored about the anti-diagonal",
         8: "rotated 90 degrees counter-clockwise"}
# LibRaw's sizes.flip -> Orientation (dcraw reads tag 274 as flip = "50132467"[value & 7])
FROM_LIBRAW_FLIP = {0: 1, 1: 2, 2: 4, 3: 3, 4: 5, 5: 8, 6: 6, 7: 7}


def check(value) -> int:
    """``value`` as an Orientation 1-8; ValueError (saying the values allowed) otherwise."""
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value in TURNS
    if not ok:
        raise ValueError(f"Orientation (tag {TAG}) {value!r} is not one of 1-8")
    return int(value)


def said(orientation: int) -> str:
    """``6 (rotated 90 degrees clockwise to stand upright)``, for logs and ``info``."""
    if orientation == 1:
        return "1 (upright as stored)"
    return f"{orientation} ({TURNS[check(orientation)]} to stand upright)"
