"""Highlights clipped in some channels only: the clipped channels rebuilt from the colour of the
nearest unclipped pixels (chroma propagation), so that a pixel where only red clipped keeps a
warm colour instead of turning white. Pixels clipped in every channel stay masked (white).

Why it generalises: a clipped photosite says only "at least the clip level"; the colour of a
surface changes slowly compared with its brightness (shading, a highlight's fall-off), so the
colour ratios of the unclipped pixels around a clipped area, applied to the channels still
measured inside it, are the best guess; the clip level is a floor no reconstruction may go
below (which also rules out magenta: a clipped green is never lower than its clip level).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

BLOCK = 4  # colours of the unclipped surroundings averaged over 4 x 4 pixels (noise)
MARGIN = 32  # pixels around the masked area searched for unclipped colour first


def rebuild_partly_clipped(rgb: np.ndarray, frame: np.ndarray, pattern: str) -> int:
    """Fill, in place, the masked (NaN) pixels of ``rgb`` (rows, cols, 3; demosaiced from the
    Bayer ``frame`` with NaN where a photosite clipped) that still have an unclipped channel.

    A channel is measured at a pixel when no photosite of its colour in the 3 x 3 neighbourhood
    is NaN (its value: the mean of those photosites); the others are clipped. A clipped channel
    gets the nearest unclipped pixels' colour ratio to the measured channels, and never less
    than its clip level (the largest finite value of its colour in the frame). Returns the
    number of pixels rebuilt.
    """
    masked = ~np.isfinite(rgb).all(axis=-1)
    if not masked.any():
        return 0
    rows, cols = np.nonzero(masked.any(axis=1))[0], np.nonzero(masked.any(axis=0))[0]
    top, bottom = max(rows[0] - MARGIN, 0), min(rows[-1] + MARGIN + 1, rgb.shape[0])
    left, right = max(cols[0] - MARGIN, 0), min(cols[-1] + MARGIN + 1, rgb.shape[1])
    top -= top % 2
    left -= left % 2  # even: the crop keeps the CFA phase of pixel (0, 0)
    window = (slice(top, bottom), slice(left, right))
    measured, clip = _measured(np.asarray(frame, np.float32), pattern, window)
    region = rgb[window]
    where = np.nonzero(masked[window])
    values = measured[where]  # (n, 3), NaN where clipped
    known = np.isfinite(values)
    partly = known.any(axis=1)
    if not partly.any():
        return 0
    ratios = _nearest_colour(region, where)
    if ratios is None:
        return 0
    values, known, ratios = values[partly], known[partly], ratios[partly]
    scale = (np.where(known, values, 0).sum(axis=1)
             / np.maximum(np.where(known, ratios, 0).sum(axis=1), 1e-12))
    rebuilt = np.where(known, values, np.maximum(scale[:, None] * ratios, clip))
    region[where[0][partly], where[1][partly]] = rebuilt
    return int(partly.sum())


def _measured(frame: np.ndarray, pattern: str, window) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of ``window`` and colour: the mean of the finite photosites of that colour in
    the 3 x 3 neighbourhood, NaN when one of them is NaN; and each colour's clip level."""
    crop = frame[window]
    out = np.full((*crop.shape, 3), np.nan, np.float32)
    clip = np.zeros(3, np.float32)
    kernel = np.ones((3, 3), np.float32)
    for c, colour in enumerate("RGB"):
        site = np.zeros(crop.shape, bool)
        for k, p in enumerate(pattern):
            if p == colour:
                site[k // 2::2, k % 2::2] = True
        finite = site & np.isfinite(crop)
        value = np.where(finite, crop, 0).astype(np.float32)
        total = cv2.filter2D(value, -1, kernel, borderType=cv2.BORDER_REFLECT)
        count = cv2.filter2D(finite.astype(np.float32), -1, kernel, borderType=cv2.BORDER_REFLECT)
        lost = cv2.filter2D((site & ~finite).astype(np.float32), -1, kernel,
                            borderType=cv2.BORDER_REFLECT)
        ok = (count > 0) & (lost == 0)
        out[..., c][ok] = total[ok] / count[ok]
        clip[c] = _clip_level(frame, pattern, colour)
    return out, clip


def _clip_level(frame: np.ndarray, pattern: str, colour: str) -> float:
    """The largest finite photosite of ``colour`` in the whole frame: just below where it
    clips (the white level above black, or what bias and flat made of it)."""
    level = 0.0
    for k, p in enumerate(pattern):
        if p == colour:
            plane = frame[k // 2::2, k % 2::2]
            level = max(level, float(np.nanmax(plane)) if np.isfinite(plane).any() else 0.0)
    return level


def _nearest_colour(region: np.ndarray, where) -> np.ndarray | None:
    """The colour (R, G, B ratios, geometric mean 1) of the nearest unclipped 4 x 4 block at
    each masked pixel ``where`` of ``region``; None when the region has no unclipped pixel."""
    rows, cols = region.shape[:2]
    pad_r, pad_c = -rows % BLOCK, -cols % BLOCK
    data = np.pad(region, ((0, pad_r), (0, pad_c), (0, 0)), constant_values=np.nan)
    blocks = data.reshape((rows + pad_r) // BLOCK, BLOCK, (cols + pad_c) // BLOCK, BLOCK, 3)
    good = np.isfinite(blocks).all(axis=-1, keepdims=True)
    count = good.sum(axis=(1, 3))
    mean = np.where(good, blocks, 0).sum(axis=(1, 3)) / np.maximum(count, 1)
    source = (count[..., 0] > 0) & (mean > 0).all(axis=-1)
    if not source.any():
        return None
    log = np.log(np.where(source[..., None], mean, 1.0))
    log -= log.mean(axis=-1, keepdims=True)
    _, (near_r, near_c) = ndimage.distance_transform_edt(~source, return_indices=True)
    br, bc = where[0] // BLOCK, where[1] // BLOCK
    return np.exp(log[near_r[br, bc], near_c[br, bc]]).astype(np.float32)
