"""Colour previews of Bayer data: the camera's white balance and colour matrix when the raw
gave them, a grey-world balance otherwise, then an sRGB picture for the PNG writer."""

from __future__ import annotations

import numpy as np

from plenocli.colour.balance import gains_from_neutral, normalised_gains
from plenocli.colour.matrix import camera_to_srgb


def display_colour(camera: np.ndarray, colour: dict | None = None, *,
                   white_percentile: float = 99.0) -> np.ndarray:
    """uint8 sRGB (rows, cols, 3) of camera RGB (rows, cols, 3); NaN shows black.

    ``colour`` is the frames' ``colour`` metadata (``as_shot_wb``, ``xyz_to_camera``); missing
    parts fall back to a grey-world balance and no matrix, so a preview never fails. The black
    point is the 0.5th percentile of the darkest channel (never below 0) when that is under half
    the highlights: raw frames still hold their black level.
    """
    rgb = np.asarray(camera, np.float32)
    finite = np.isfinite(rgb).all(axis=-1)
    if not finite.any():
        return np.zeros(rgb.shape, np.uint8)
    # raw frames still hold their black level: a low percentile is the preview's black point
    # (taken off only when it is well below the highlights: a uniform white keeps its level)
    black = max(0.0, float(np.percentile(rgb[finite].min(axis=-1), 0.5)))
    if black < 0.5 * float(np.percentile(rgb[finite].max(axis=-1), 99.0)):
        rgb = rgb - np.float32(black)
    colour = colour or {}
    try:
        gains = normalised_gains(colour["as_shot_wb"])
    except (KeyError, TypeError, ValueError):
        try:
            gains = gains_from_neutral(rgb[finite].mean(axis=0))
        except ValueError:
            gains = np.ones(3)
    combined = np.diag(gains)
    try:
        combined = camera_to_srgb(colour["xyz_to_camera"]) @ combined
    except (KeyError, TypeError, ValueError):
        pass
    out = np.nan_to_num(rgb @ combined.T.astype(np.float32), nan=0.0)
    reference = float(np.percentile(out[finite], white_percentile))
    out = np.clip(out / max(reference, 1e-12), 0.0, 1.0)
    out = np.where(out <= 0.0031308, 12.92 * out, 1.055 * np.power(out, 1 / 2.4) - 0.055)
    return np.round(255 * out).astype(np.uint8)
