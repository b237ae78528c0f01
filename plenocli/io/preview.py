"""PNG previews: a quick look at a result, never an input to another stage."""

from __future__ import annotations

import os

import cv2
import numpy as np

from plenocli.io.atomic import atomic_path
from plenocli.model.cfa import half_size_rgb


def to_display(image: np.ndarray, *, low: float = 0.5, high: float = 99.5,
               gamma: float = 2.2) -> np.ndarray:
    """Stretch an image to uint8 between two percentiles, with a display gamma; NaN shows black."""
    finite = image[np.isfinite(image)]
    if finite.size == 0:
        return np.zeros(image.shape, np.uint8)
    lo, hi = np.percentile(finite, [low, high])
    scaled = np.clip((np.nan_to_num(image, nan=lo) - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
    return np.round(255.0 * scaled ** (1.0 / gamma)).astype(np.uint8)


def views_side_by_side(views: np.ndarray, cfa: str | None = None, *, gap: int = 4) -> np.ndarray:
    """Views (views, rows, cols) as one picture, left to right, with NaN gaps between them."""
    tiles = [half_size_rgb(v, cfa) if cfa else np.asarray(v, np.float32) for v in views]
    spacer = np.full((tiles[0].shape[0], gap, *tiles[0].shape[2:]), np.nan, np.float32)
    out = [tiles[0]]
    for tile in tiles[1:]:
        out += [spacer, tile]
    return np.concatenate(out, axis=1)


def write_png(path: str | os.PathLike, image: np.ndarray, *, cfa: str | None = None,
              max_side: int = 2048, protect: tuple = ()) -> None:
    """Write a display PNG of a 2-D frame (Bayer if ``cfa``), an (rows, cols, 3) RGB image, or
    (views, rows, cols) views side by side."""
    if image.ndim == 3 and image.shape[-1] != 3:
        image, cfa = views_side_by_side(image, cfa), None
    img = np.asarray(half_size_rgb(image, cfa) if cfa and image.ndim == 2 else image, np.float32)
    scale = max(img.shape[:2]) / max_side
    if scale > 1:  # shrink first: the stretch below then works on a few megapixels, not 60
        size = (round(img.shape[1] / scale), round(img.shape[0] / scale))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    img = to_display(img)
    if img.ndim == 3:
        img = img[..., ::-1]  # OpenCV writes BGR
    with atomic_path(path, protect=protect) as tmp:
        ok, buf = cv2.imencode(".png", img)
        if not ok:
            raise OSError(f"could not encode PNG for {path}")
        tmp.write_bytes(buf.tobytes())


def write_grid_overlay(path: str | os.PathLike, flat: np.ndarray, centres: np.ndarray,
                       pitch_px: float, *, protect: tuple = ()) -> None:
    """A flattened image (display-stretched, at most 2048 px) with every lens centre (K, 2)
    (x, y) px drawn as a red dot: a wrong grid shows at a glance."""
    grey = to_display(flat, gamma=1.0)
    scale = min(1.0, 2048 / max(grey.shape))
    if scale < 1:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    bgr = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    shift = 4  # sub-pixel drawing
    radius = max(1, int(pitch_px * scale / 8)) << shift
    for x, y in np.asarray(centres) * scale:
        cv2.circle(bgr, (int(round(x * (1 << shift))), int(round(y * (1 << shift)))), radius,
                   (0, 0, 255), -1, cv2.LINE_AA, shift)
    ok, buf = cv2.imencode(".png", bgr)
    if not ok:
        raise OSError(f"could not encode PNG for {path}")
    with atomic_path(path, protect=protect) as tmp:
        tmp.write_bytes(buf.tobytes())
