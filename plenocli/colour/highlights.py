"""Highlights clipped in some channels only: the clipped channels rebuilt from the colour of the
nearest unclipped pixels (chroma propagation), so that a pixel where only red clipped keeps a
warm colour instead of turning white. Pixels clipped in every channel stay masked (white).

Why it generalises: a clipped photosite says only "at least the clip level"; the colour of a
surface changes slowly compared with its brightness (shading, a highlight's fall-off), so the
colour ratios of the unclipped pixels around a clipped area, applied to the channels still
measured inside it, are the best guess; the clip level is a floor no reconstruction may go
below. Measured figures: docs/colour.md (Clipped highlights).
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

BAND_ROWS = 512  # rows measured at a time: bounds the scratch memory
BLOCK = 4  # colours of the unclipped surroundings averaged over 4 x 4 pixels (noise)
MARGIN = 32  # pixels around the masked area searched for unclipped colour first
BRIGHT = 0.25  # unclipped colour taken from pixels within two stops of the lowest clip level


class Estimated:
    """Which channels of which pixels of a view the rebuild estimated (a clipped or unknown
    channel, floored at the clip level) rather than measured: one bit per pixel and channel
    (at 6876 x 4584 px 3.9 MB a channel where a bool mask takes 31.5 MB), allocated for a
    channel once a pixel of it is estimated. What compares views by their light (the stitch's
    exposure gains) takes measured values only: an estimate is a colour guessed from the
    surroundings, or the clip level, not the view's light."""

    def __init__(self, shape: tuple[int, int]):
        self.shape = (int(shape[0]), int(shape[1]))
        self.bits: list[np.ndarray | None] = [None, None, None]

    def mark(self, rows: np.ndarray, cols: np.ndarray, channels: np.ndarray) -> None:
        """Mark pixels (rows, cols: sorted by row, as ``np.nonzero`` gives them) as estimated
        in the channels ``channels`` (n, 3) bool; BAND_ROWS rows at a time (bounded scratch)."""
        width = self.shape[1]
        for c in range(3):
            r, k = rows[channels[:, c]], cols[channels[:, c]]
            if not len(r):
                continue
            if self.bits[c] is None:
                self.bits[c] = np.zeros((self.shape[0], -(-width // 8)), np.uint8)
            for start in range(int(r[0]), int(r[-1]) + 1, BAND_ROWS):
                lo, hi = np.searchsorted(r, (start, start + BAND_ROWS))
                if lo == hi:
                    continue
                mask = np.zeros((min(BAND_ROWS, self.shape[0] - start), width), bool)
                mask[r[lo:hi] - start, k[lo:hi]] = True
                self.bits[c][start:start + len(mask)] |= np.packbits(mask, axis=1)

    def region(self, channel: int, rows: slice, cols: slice) -> np.ndarray | None:
        """Where ``channel`` is estimated in the view's pixels [rows, cols] (bool), or None
        when none of it is anywhere."""
        bits = self.bits[channel]
        if bits is None:
            return None
        first = cols.start // 8
        out = np.unpackbits(bits[rows, first:-(-cols.stop // 8)], axis=1)
        return out[:, cols.start - 8 * first:cols.stop - 8 * first].view(bool)


def rebuild_partly_clipped(rgb: np.ndarray, frame: np.ndarray, pattern: str, gains,
                           estimated: Estimated | None = None) -> int:
    """Fill, in place, the masked (NaN) pixels of ``rgb`` (rows, cols, 3; demosaiced from the
    Bayer ``frame`` with NaN where a photosite clipped) that still have an unclipped channel.

    A channel is measured at a pixel when no photosite of its colour in the 3 x 3 neighbourhood
    is NaN (:func:`_measured`); the others are clipped. A clipped channel gets the colour ratio
    to the measured channels of the nearest unclipped block bright enough to be the same
    surface (grey when only one channel is measured: two ratios from one value are guesses),
    and never less than its neighbouring photosites allow (clipped ones at the clip level, the
    largest finite value of their colour in the frame; channels clipped together, white
    balanced by ``gains``, at the highest of their floors), nor, white balanced, than
    the darkest measured channel: a channel that clipped is not the pixel's darkest (a clipped
    green below red and blue is the magenta of a badly developed highlight). Returns the number
    of pixels rebuilt; ``estimated`` (:class:`Estimated`, the shape of ``rgb``) is told which
    channels of them are estimates.
    """
    # nothing clipped: one cheap pass (a float32 sum that overflows only takes the long way)
    if np.isfinite(np.sum(frame)):
        return 0
    masked = ~np.isfinite(rgb).all(axis=-1)
    if not masked.any():
        return 0
    rows, cols = np.nonzero(masked.any(axis=1))[0], np.nonzero(masked.any(axis=0))[0]
    top, bottom = max(rows[0] - MARGIN, 0), min(rows[-1] + MARGIN + 1, rgb.shape[0])
    left, right = max(cols[0] - MARGIN, 0), min(cols[-1] + MARGIN + 1, rgb.shape[1])
    top -= top % 2
    left -= left % 2  # even: the crop keeps the CFA phase of pixel (0, 0)
    window = (slice(top, bottom), slice(left, right))
    frame = np.asarray(frame, np.float32)
    gains = np.asarray(gains, np.float32)
    clip = np.array([_clip_level(frame, pattern, c) for c in "RGB"], np.float32)
    region = rgb[window]
    where = np.nonzero(masked[window])
    values, floor = _measured_at(frame, pattern, window, gains, clip, where)
    known = np.isfinite(values)
    partly = known.any(axis=1)
    if not partly.any():
        return 0
    bright = BRIGHT * float((clip * gains).min())
    ratios = _nearest_colour(region, where, gains, bright)
    values, known, ratios = values[partly], known[partly], ratios[partly]
    scale = (np.where(known, values, 0).sum(axis=1)
             / np.maximum(np.where(known, ratios, 0).sum(axis=1), 1e-12))
    darkest = np.where(known, values * gains, np.inf).min(axis=1, keepdims=True) / gains
    floor = np.maximum(floor[partly], darkest)
    # two unknowns from one measurement: grey at the measured level, the clipped channels at
    # one white-balanced floor, the highest of theirs (each at its own, they are as unequal as
    # the gains: pink where red and green clipped over blue)
    alone = known.sum(axis=1) == 1
    ratios[alone] = 1.0 / gains
    scale[alone] = np.where(known[alone], values[alone] * gains, 0).sum(axis=1)
    shared = np.where(known, 0, floor * gains).max(axis=1, keepdims=True) / gains
    floor = np.where(known | ~alone[:, None], floor, np.maximum(floor, shared))
    rebuilt = np.where(known, values, np.maximum(scale[:, None] * ratios, floor))
    region[where[0][partly], where[1][partly]] = rebuilt
    if estimated is not None:
        estimated.mark(where[0][partly] + top, where[1][partly] + left, ~known)
    return int(partly.sum())


def _measured_at(frame, pattern: str, window, gains, clip, where):
    """:func:`_measured` at the pixels ``where`` of ``window``, band by band (bounded
    scratch); a 2-row margin (even: the CFA phase is kept) covers the 3 x 3 neighbourhoods."""
    values = np.empty((len(where[0]), 3), np.float32)
    floor = np.empty_like(values)
    top, bottom = window[0].start, window[0].stop
    for start in range(top, bottom, BAND_ROWS):
        stop = min(start + BAND_ROWS, bottom)
        inside = (where[0] >= start - top) & (where[0] < stop - top)
        if not inside.any():
            continue
        first = max(start - 2, 0)
        band = (slice(first, min(stop + 2, frame.shape[0])), window[1])
        measured, lower = _measured(frame, pattern, band, gains, clip)
        at = (where[0][inside] + top - first, where[1][inside])
        values[inside], floor[inside] = measured[at], lower[at]
    return values, floor


def _measured(frame: np.ndarray, pattern: str, window, gains, clip
              ) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of ``window`` and colour: its value interpolated from the photosites of that
    colour in the 3 x 3 neighbourhood, NaN when one of them is NaN (clipped); and its lower
    bound, the least of those photosites with every clipped one at its ``clip`` level (at an
    edge the pixel can be darker than their mean). Green is the mean of its photosites (the
    pixel's own, or its four neighbours); red and blue are green plus the mean colour
    difference of their photosites, white balanced (bright and dark change all channels
    together: no fringes where a highlight meets a dark edge), or their plain mean where green
    is unknown."""
    crop = frame[window]
    out = np.empty((*crop.shape, 3), np.float32)
    lower = np.empty((*crop.shape, 3), np.float32)
    for c, colour in enumerate("RGB"):
        site = _sites(crop.shape, pattern, colour)
        floor = np.where(site, np.where(np.isnan(crop), clip[c], crop), np.inf)
        lower[..., c] = cv2.erode(floor.astype(np.float32),
                                  (_CROSS if c == 1 else _SQUARE).astype(np.uint8))
    green, green_lost = _mean(crop * np.float32(gains[1]), _sites(crop.shape, pattern, "G"),
                              _CROSS)
    out[..., 1] = np.where(green_lost, np.nan, green / np.float32(gains[1]))
    for c in (0, 2):
        site = _sites(crop.shape, pattern, "RGB"[c])
        value = crop * np.float32(gains[c])
        plain, lost = _mean(value, site, _SQUARE)
        difference, differences_lost = _mean(value - green, site & ~green_lost, _SQUARE)
        rebuilt = np.where(differences_lost | green_lost, plain, green + difference)
        out[..., c] = np.where(lost, np.nan, rebuilt / np.float32(gains[c]))
    return out, lower


_SQUARE = np.ones((3, 3), np.float32)
_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.float32)


def _sites(shape, pattern: str, colour: str) -> np.ndarray:
    site = np.zeros(shape, bool)
    for k, p in enumerate(pattern):
        if p == colour:
            site[k // 2::2, k % 2::2] = True
    return site


def _mean(values: np.ndarray, site: np.ndarray, kernel: np.ndarray):
    """The mean of the finite ``values`` at ``site`` under ``kernel``, and where one of those
    sites is not finite (or none is under it)."""
    finite = site & np.isfinite(values)
    total = cv2.filter2D(np.where(finite, values, 0).astype(np.float32), -1, kernel,
                         borderType=cv2.BORDER_REFLECT)
    count = cv2.filter2D(finite.astype(np.float32), -1, kernel, borderType=cv2.BORDER_REFLECT)
    sites = cv2.filter2D(site.astype(np.float32), -1, kernel, borderType=cv2.BORDER_REFLECT)
    return total / np.maximum(count, 1), (count == 0) | (count < sites)


def _clip_level(frame: np.ndarray, pattern: str, colour: str) -> float:
    """The largest finite photosite of ``colour`` in the whole frame: just below where it
    clips (the white level above black, or what bias and flat made of it)."""
    level = 0.0
    for k, p in enumerate(pattern):
        if p == colour:
            plane = frame[k // 2::2, k % 2::2]
            level = max(level, float(np.nanmax(plane)) if np.isfinite(plane).any() else 0.0)
    return level


def _nearest_colour(region: np.ndarray, where, gains: np.ndarray, bright: float) -> np.ndarray:
    """The colour (R, G, B ratios, geometric mean 1) of the nearest unclipped 4 x 4 block at
    each masked pixel ``where`` of ``region``, among the blocks whose brightest white-balanced
    channel reaches ``bright`` (the surface around a highlight, not a dark object next to it);
    grey (1 / gains) where the region has none."""
    mean, count = _block_means(region)
    source = ((count > 0) & (mean > 0).all(axis=-1)
              & ((mean * gains).max(axis=-1) >= bright))
    if not source.any():
        return np.broadcast_to(1.0 / gains, (len(where[0]), 3)).copy()
    log = np.log(np.where(source[..., None], mean, 1.0))
    log -= log.mean(axis=-1, keepdims=True)
    _, (near_r, near_c) = ndimage.distance_transform_edt(~source, return_indices=True)
    br, bc = where[0] // BLOCK, where[1] // BLOCK
    return np.exp(log[near_r[br, bc], near_c[br, bc]]).astype(np.float32)


def _block_means(region: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mean RGB of the finite pixels of each BLOCK x BLOCK block, and their number; band by
    band (bounded scratch)."""
    rows, cols = region.shape[:2]
    shape = (-(-rows // BLOCK), -(-cols // BLOCK))
    mean, count = np.zeros((*shape, 3), np.float32), np.zeros(shape, np.int32)
    for start in range(0, rows, BAND_ROWS):
        band = region[start:start + BAND_ROWS]
        pad = ((0, -band.shape[0] % BLOCK), (0, -cols % BLOCK), (0, 0))
        blocks = np.pad(band, pad, constant_values=np.nan).reshape(
            -1, BLOCK, shape[1], BLOCK, 3)
        good = np.isfinite(blocks).all(axis=-1, keepdims=True)
        n = good.sum(axis=(1, 3))
        out = slice(start // BLOCK, start // BLOCK + blocks.shape[0])
        mean[out] = np.where(good, blocks, 0).sum(axis=(1, 3)) / np.maximum(n, 1)
        count[out] = n[..., 0]
    return mean, count
