"""Compositing: the panorama canvas, every view warped into it, exposure matched from the
overlaps, the canvas trimmed to what the views cover, and the seams blended (feathering or
Burt-Adelson multi-band).

Memory: the panorama is built view by view and band by band. A view is resampled in bands of
rows (about ``BAND_PIXELS`` canvas pixels) and added, weighted, into the panorama; only its
feather weight is kept, within its footprint. The exposure gains and the residuals need the
views together only over each pair's overlap, which is resampled on its own. Resampling a band
of a box is resampling the box (the warps' coordinates differ by whole pixels), so the bands
change nothing but the memory: the peak is the panorama, its weights and one band.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from plenocli.errors import InputError
from plenocli.stitch.quality import bounding_box
from plenocli.stitch.registration import difference_row
from plenocli.stitch.views import corners_xy, translation_matrix

BAND_PIXELS = 1 << 20  # canvas pixels resampled at a time


@dataclass(frozen=True)
class Placement:
    """A view on the canvas: the box (row slice, column slice) its footprint covers, with 4 px
    for the resampling kernels, and ``matrix`` (3 x 3) mapping view pixels to box pixels."""

    box: tuple[slice, slice]
    matrix: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return self.box[0].stop - self.box[0].start, self.box[1].stop - self.box[1].start


@dataclass(frozen=True)
class Layers:
    """The views placed on the (trimmed) canvas: each view's placement and feather weight
    (float32, the box's shape; 0 outside the view), and their sum over the canvas."""

    places: list[Placement]
    weights: list[np.ndarray]
    total: np.ndarray

    def weight_on(self, k: int, region: tuple[slice, slice]) -> np.ndarray:
        """View k's weight over a canvas ``region`` (0 outside its box)."""
        out = np.zeros((region[0].stop - region[0].start, region[1].stop - region[1].start),
                       np.float32)
        inner = _intersect(self.places[k].box, region)
        if inner is not None:
            out[_relative(inner, region)] = self.weights[k][_relative(inner, self.places[k].box)]
        return out


def canvas(transforms: list[np.ndarray], shape: tuple[int, int]) -> tuple[np.ndarray, tuple]:
    """Translation view-0 coordinates -> panorama pixels, and the panorama (rows, cols)."""
    rows, cols = shape
    pts = np.concatenate([cv2.perspectiveTransform(corners_xy(shape), t).reshape(-1, 2)
                          for t in transforms])
    x0, y0 = np.floor(pts.min(axis=0) + 1e-6)
    x1, y1 = np.floor(pts.max(axis=0) + 1e-6)
    out_shape = (int(y1 - y0) + 1, int(x1 - x0) + 1)
    if out_shape[0] * out_shape[1] > 16 * rows * cols * len(transforms):
        raise InputError(f"the transforms spread the views over {out_shape[1]} x {out_shape[0]} "
                         "px; the registration failed (views without a true overlap?)")
    return translation_matrix(-y0, -x0), out_shape


def placement(m: np.ndarray, shape: tuple[int, int], out_shape: tuple[int, int]) -> Placement:
    """The canvas box a view of ``shape`` covers under ``m`` (view pixels -> canvas pixels)."""
    pts = cv2.perspectiveTransform(corners_xy(shape), m).reshape(-1, 2)
    x0, y0 = (max(0, int(np.floor(v)) - 4) for v in pts.min(axis=0))
    x1 = min(out_shape[1], int(np.ceil(pts[:, 0].max())) + 5)
    y1 = min(out_shape[0], int(np.ceil(pts[:, 1].max())) + 5)
    x1, y1 = max(x1, x0 + 1), max(y1, y0 + 1)
    return Placement((slice(y0, y1), slice(x0, x1)), translation_matrix(-y0, -x0) @ m)


def _intersect(a: tuple[slice, slice], b: tuple[slice, slice]) -> tuple[slice, slice] | None:
    rows = slice(max(a[0].start, b[0].start), min(a[0].stop, b[0].stop))
    cols = slice(max(a[1].start, b[1].start), min(a[1].stop, b[1].stop))
    return (rows, cols) if rows.stop > rows.start and cols.stop > cols.start else None


def _relative(region: tuple[slice, slice], box: tuple[slice, slice]) -> tuple[slice, slice]:
    """``region`` (canvas slices) in the coordinates of ``box``."""
    return (slice(region[0].start - box[0].start, region[0].stop - box[0].start),
            slice(region[1].start - box[1].start, region[1].stop - box[1].start))


def _feather_weight(valid: np.ndarray) -> np.ndarray:
    """Distance (px) to the nearest invalid pixel or the view's border, float32 (exact
    Euclidean distance transform)."""
    if valid.all():  # the distance to the border, without a distance transform
        rows, cols = valid.shape
        to_y = np.minimum(np.arange(1, rows + 1), np.arange(rows, 0, -1)).astype(np.float32)
        to_x = np.minimum(np.arange(1, cols + 1), np.arange(cols, 0, -1)).astype(np.float32)
        return np.minimum(to_y[:, None], to_x[None, :])
    padded = np.pad(valid.view(np.uint8), 1)
    return cv2.distanceTransform(padded, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)[1:-1, 1:-1]


def _warp(image: np.ndarray, m: np.ndarray, out_shape: tuple[int, int], *, interp: int,
          border: int = cv2.BORDER_REPLICATE) -> np.ndarray:
    size = (out_shape[1], out_shape[0])
    if np.allclose(m[2], [0, 0, 1]):
        return cv2.warpAffine(image, m[:2].astype(np.float64), size, flags=interp,
                              borderMode=border, borderValue=0)
    return cv2.warpPerspective(image, m, size, flags=interp, borderMode=border, borderValue=0)


def _bands(region: tuple[slice, slice]) -> Iterator[tuple[slice, slice]]:
    """``region`` cut into bands of whole rows of about BAND_PIXELS pixels."""
    rows, cols = region
    step = max(1, BAND_PIXELS // max(1, cols.stop - cols.start))
    for r0 in range(rows.start, rows.stop, step):
        yield slice(r0, min(r0 + step, rows.stop)), cols


def _region_shape(region: tuple[slice, slice]) -> tuple[int, int]:
    return region[0].stop - region[0].start, region[1].stop - region[1].start


def _view_weight(valid: np.ndarray, place: Placement) -> np.ndarray:
    """A view's feather weight (distance to its edge, bilinear) over its box, 0 where the view
    does not fully cover a canvas pixel."""
    src_valid = valid.astype(np.float32)
    src_weight = _feather_weight(valid)
    weight = np.empty(place.shape, np.float32)
    for band in _bands((slice(0, place.shape[0]), slice(0, place.shape[1]))):
        m = translation_matrix(-band[0].start, 0) @ place.matrix
        shape = _region_shape(band)
        cover = _warp(src_valid, m, shape, interp=cv2.INTER_LINEAR,
                      border=cv2.BORDER_CONSTANT) > 0.999
        weight[band] = np.where(cover, _warp(src_weight, m, shape, interp=cv2.INTER_LINEAR), 0)
    return weight


def place_views(valid: Sequence[np.ndarray], transforms: list[np.ndarray], offset: np.ndarray,
                pano_shape: tuple[int, int]) -> Layers:
    """Every view's placement and feather weight on the canvas (``valid``: each view's
    (rows, cols) pixels with data), and the weights' sum."""
    places = [placement(offset @ t, valid[0].shape, pano_shape) for t in transforms]
    weights = [_view_weight(v, p) for v, p in zip(valid, places, strict=True)]
    total = np.zeros(pano_shape, np.float32)
    for p, w in zip(places, weights, strict=True):
        total[p.box] += w
    return Layers(places, weights, total)


def trim_to_coverage(layers: Layers, offset: np.ndarray) -> tuple[Layers, np.ndarray]:
    """The canvas cropped to what the views cover (rig canvases are generous): the layers on
    the cropped canvas and the view-0 -> panorama translation."""
    box = bounding_box(layers.total > 0)
    if box is None or _region_shape(box) == layers.total.shape:
        return layers, offset
    r0, c0 = box[0].start, box[1].start
    offset = offset.copy()
    offset[0, 2] -= c0
    offset[1, 2] -= r0
    places = [Placement((slice(p.box[0].start - r0, p.box[0].stop - r0),
                         slice(p.box[1].start - c0, p.box[1].stop - c0)), p.matrix)
              for p in layers.places]
    return Layers(places, layers.weights, layers.total[box]), offset


def warp_region(view: np.ndarray, place: Placement, region: tuple[slice, slice]) -> np.ndarray:
    """(C, rows, cols) float32: a view's channels (C, rows, cols; no NaN) resampled
    (Lanczos-4) onto a canvas ``region`` inside its box."""
    rel = _relative(region, place.box)
    m = translation_matrix(-rel[0].start, -rel[1].start) @ place.matrix
    shape = _region_shape(region)
    return np.stack([_warp(channel, m, shape, interp=cv2.INTER_LANCZOS4) for channel in view])


def pair_overlaps(layers: Layers, pairs: list[tuple[int, int, str]]):
    """Per neighbour pair: (canvas region, the pixels both views cover in it) or None."""
    out = []
    for a, b, _ in pairs:
        inner = _intersect(layers.places[a].box, layers.places[b].box)
        inner = None if inner is None else _intersect(inner, (slice(0, layers.total.shape[0]),
                                                              slice(0, layers.total.shape[1])))
        both = None if inner is None else ((layers.weight_on(a, inner) > 0)
                                           & (layers.weight_on(b, inner) > 0))
        box = None if both is None else bounding_box(both)
        if box is None:
            out.append(None)
            continue
        region = (slice(inner[0].start + box[0].start, inner[0].start + box[0].stop),
                  slice(inner[1].start + box[1].start, inner[1].start + box[1].stop))
        out.append((region, both[box]))
    return out


def match_gains(views: Sequence[np.ndarray], layers: Layers, pairs: list[tuple[int, int, str]],
                overlaps: list) -> np.ndarray:
    """Per-view, per-channel gains from overlap means (log least squares, view 0 fixed)."""
    n_views, n_chan = len(views), views[0].shape[0]
    means = []
    for (a, b, _), overlap in zip(pairs, overlaps, strict=True):
        if overlap is None:
            means.append(None)
            continue
        region, both = overlap
        crop_a = warp_region(views[a], layers.places[a], region)
        crop_b = warp_region(views[b], layers.places[b], region)
        means.append([(float(crop_a[c][both].mean()), float(crop_b[c][both].mean()))
                      for c in range(n_chan)])
    gains = np.ones((n_views, n_chan))
    for c in range(n_chan):
        rows, rhs = [], []
        for (a, b, _), pair_means in zip(pairs, means, strict=True):
            mean_a, mean_b = pair_means[c] if pair_means is not None else (0.0, 0.0)
            if mean_a <= 0 or mean_b <= 0:
                continue  # no usable overlap or signed data: leave this pair out
            rows.append(difference_row(a, b, n_views))
            rhs.append(np.log(mean_a / mean_b))
        if rows:
            sol, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
            gains[1:, c] = np.exp(sol)
    return gains


def overlap_luminance(views: Sequence[np.ndarray], layers: Layers, view: int,
                      region: tuple[slice, slice], gains: np.ndarray) -> np.ndarray:
    """The channel mean of a view, exposure-matched, over a canvas region."""
    crop = warp_region(views[view], layers.places[view], region)
    crop *= gains[view].astype(np.float32)[:, None, None]
    return crop.mean(axis=0)


def blend(views: Sequence[np.ndarray], layers: Layers, gains: np.ndarray,
          method: str) -> np.ndarray:
    """The panorama (C, rows, cols) float32 from the views (each (C, rows, cols), NaN
    filled), their layers and gains: feathering (weighted mean) or multi-band; NaN where no
    view covers it."""
    if method == "multiband":
        return _multiband_blend(views, layers, gains)
    n_chan = views[0].shape[0]
    panorama = np.zeros((n_chan,) + layers.total.shape, np.float32)
    canvas_box = (slice(0, layers.total.shape[0]), slice(0, layers.total.shape[1]))
    for view, place, weight, gain in zip(views, layers.places, layers.weights, gains,
                                         strict=True):
        inner = _intersect(place.box, canvas_box)
        if inner is None:
            continue
        for band in _bands(inner):
            img = warp_region(view, place, band)
            img *= gain.astype(np.float32)[:, None, None]
            img *= weight[_relative(band, place.box)]
            panorama[(slice(None),) + band] += img
    for band in _bands(canvas_box):
        total = layers.total[band]
        panorama[(slice(None),) + band] *= 1.0 / np.maximum(total, 1e-12)
        panorama[(slice(None),) + band][:, total <= 0] = np.nan
    return panorama


def _multiband_blend(views: Sequence[np.ndarray], layers: Layers,
                     gains: np.ndarray) -> np.ndarray:
    """Multi-band blend, channel by channel over the whole canvas (V canvases per channel)."""
    shape = layers.total.shape
    canvas_box = (slice(0, shape[0]), slice(0, shape[1]))
    weights = np.stack([layers.weight_on(k, canvas_box) for k in range(len(views))])
    covered = layers.total > 0
    inv_total = 1.0 / np.maximum(layers.total, 1e-12)
    panorama = np.full((views[0].shape[0],) + shape, np.nan, np.float32)
    for c in range(views[0].shape[0]):
        images = np.zeros((len(views),) + shape, np.float32)
        for k, (view, place) in enumerate(zip(views, layers.places, strict=True)):
            inner = _intersect(place.box, canvas_box)
            if inner is None:
                continue
            img = warp_region(view[c:c + 1], place, inner)[0]
            img *= np.float32(gains[k, c])
            images[k][inner] = np.where(weights[k][inner] > 0, img, 0)
        feather = np.zeros(shape, np.float32)
        for k in range(len(views)):
            feather += images[k] * weights[k]
        feather *= inv_total
        panorama[c] = np.where(covered, _multiband(images, weights, feather), np.nan)
    return panorama


def _multiband(images: np.ndarray, weights: np.ndarray, fallback: np.ndarray,
               levels: int = 5) -> np.ndarray:
    """Burt-Adelson blend of (V, rows, cols) images with seam masks (winner-takes-all weights)."""
    rows, cols = fallback.shape
    levels = max(1, min(levels, int(np.log2(max(2, min(rows, cols) // 16)))))
    winner = np.argmax(weights, axis=0)
    covered = weights.max(axis=0) > 0
    num = None
    den = None
    for k in range(images.shape[0]):
        img = np.where(weights[k] > 0, images[k], fallback).astype(np.float32)
        mask = ((winner == k) & covered).astype(np.float32)
        gauss_img, gauss_mask = [img], [mask]
        for _ in range(levels):
            gauss_img.append(cv2.pyrDown(gauss_img[-1]))
            gauss_mask.append(cv2.pyrDown(gauss_mask[-1]))
        lap = []
        for lvl in range(levels):
            size = (gauss_img[lvl].shape[1], gauss_img[lvl].shape[0])
            lap.append(gauss_img[lvl] - cv2.pyrUp(gauss_img[lvl + 1], dstsize=size))
        lap.append(gauss_img[-1])
        terms = [lp * gm for lp, gm in zip(lap, gauss_mask, strict=True)]
        num = terms if num is None else [n + t for n, t in zip(num, terms, strict=True)]
        den = gauss_mask if den is None else [d + g for d, g in zip(den, gauss_mask, strict=True)]
    bands = [n / np.maximum(d, 1e-6) for n, d in zip(num, den, strict=True)]
    out = bands[-1]
    for lvl in range(levels - 1, -1, -1):
        size = (bands[lvl].shape[1], bands[lvl].shape[0])
        out = cv2.pyrUp(out, dstsize=size) + bands[lvl]
    return out


