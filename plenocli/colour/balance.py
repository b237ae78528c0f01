"""White balance: per-channel gains that make a neutral surface neutral in camera RGB.

Gains are multipliers of camera R, G, B normalised to green = 1 (the convention of dcraw and
LibRaw's ``camera_whitebalance``). They come from the raw's as-shot metadata, from the user
(``--wb R,G,B``), or are measured on a white or grey target (``--wb-from WHITE.tif``).
"""

from __future__ import annotations

import numpy as np

from plenocli.errors import numbers
from plenocli.model.colour import MAX_GAIN_RATIO, gains_from_neutral, normalised_gains


def gains_from_mosaic(frame: np.ndarray, cfa: str, *, centre_fraction: float = 0.5
                      ) -> np.ndarray:
    """Gains from a Bayer frame of a white (or grey) target: the mean of each colour over the
    central ``centre_fraction`` of the frame (NaN pixels ignored)."""
    data = np.asarray(frame, np.float64)
    rows, cols = data.shape
    if not 0 < centre_fraction <= 1:
        raise ValueError(f"centre_fraction must be in (0, 1], got {centre_fraction}")
    r0 = int(rows * (1 - centre_fraction) / 2) // 2 * 2
    c0 = int(cols * (1 - centre_fraction) / 2) // 2 * 2
    centre = data[r0:rows - r0, c0:cols - c0]
    sums = np.zeros(3)
    counts = np.zeros(3)
    for k, colour in enumerate(cfa.upper()):
        plane = centre[k // 2::2, k % 2::2]
        finite = plane[np.isfinite(plane)]
        sums["RGB".index(colour)] += finite.sum()
        counts["RGB".index(colour)] += finite.size
    if np.any(counts == 0):
        raise ValueError("the white frame has no finite pixel of some colour in its centre")
    return gains_from_neutral(_measured(sums / counts))


def gains_from_rgb(rgb: np.ndarray, *, centre_fraction: float = 0.5) -> np.ndarray:
    """Gains from an RGB image (rows, cols, 3) of a white or grey target (central part)."""
    data = np.asarray(rgb, np.float64)
    rows, cols = data.shape[:2]
    r0, c0 = int(rows * (1 - centre_fraction) / 2), int(cols * (1 - centre_fraction) / 2)
    centre = data[r0:rows - r0, c0:cols - c0].reshape(-1, 3)
    centre = centre[np.isfinite(centre).all(axis=1)]
    if centre.size == 0:
        raise ValueError("the white image has no finite pixel in its centre")
    return gains_from_neutral(_measured(centre.mean(axis=0)))


def _measured(neutral: np.ndarray) -> np.ndarray:
    """The white's mean per colour, refused in words when a colour holds no light (a mean at or
    below zero: that colour's sites are at or below black, so no gain can balance it) or too
    little to measure a gain by (under 1/MAX_GAIN_RATIO of the brightest colour's: the rule
    --wb and as-shot gains follow; a red 2 DN above black gave a gain of 3744, exit 0)."""
    names = ("red", "green", "blue")
    dark = [name for name, value in zip(names, neutral, strict=True) if not value > 0]
    if dark:
        raise ValueError(f"the white's {' and '.join(dark)} sites average "
                         f"{numbers(v for v in neutral if not v > 0)} (at or below black): it "
                         "holds no light of that colour; use a white lit in every colour, above "
                         "black and not clipped")
    faint = [k for k, value in enumerate(neutral) if value * MAX_GAIN_RATIO < neutral.max()]
    if faint:
        raise ValueError(f"the white's {' and '.join(names[k] for k in faint)} sites average "
                         f"{numbers(neutral[faint])}, under 1/{MAX_GAIN_RATIO:g} of its "
                         f"{names[int(np.argmax(neutral))]} ({numbers([neutral.max()])}): a gain "
                         "measured on so little light is noise; use a white lit in every colour")
    return neutral


def apply_gains(rgb: np.ndarray, gains) -> np.ndarray:
    """``rgb`` (..., 3) times the gains, as a new float32 array."""
    return np.asarray(rgb, np.float32) * normalised_gains(gains).astype(np.float32)
