"""The one coordinate map of each view: panorama pixel -> view pixel, in one step.

A view reaches the panorama through three geometric steps: its undistortion (a prism rig's
common frame, or a known radial distortion), its registered transform to the reference view, and
the canvas placement. :class:`ViewMap` composes them, so every panorama pixel of the view's
footprint is resampled once (Lanczos-4, ``cv2.remap`` with float32 maps, band by band) from the
view as recorded; nothing is interpolated twice.

``to_frame`` (3 x 3) takes a panorama pixel (x, y, 1) to the view's *frame*: the rig's common
undistorted frame (with a rig), the undistorted view pixel (with a radial distortion) or the view
pixel itself. The frame is then taken to the recorded view pixel by the rig's ray model (on its
node grid when ``to_frame`` is a pure shift, ray by ray otherwise) or the distortion formula.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from plenocli.stitch.kernels import edge_weight, matrix_maps
from plenocli.stitch.rig import (
    PrismRig,
    _view_maps,
    common_to_view,
    view_to_common,
)

BAND_PIXELS = 1 << 20  # panorama pixels mapped and resampled at a time (OpenCV's remap slows
# on thin bands: 35 rows took 1.36 x one call, 256 rows 1.07 x)
COVER_EPS_PX = 1.0 / 64  # a source coordinate this far past the view's last pixel still counts


@dataclass(frozen=True)
class ViewMap:
    """Panorama pixel -> recorded view pixel for one view (see the module docstring)."""

    view_shape: tuple[int, int]
    to_frame: np.ndarray
    k1: float = 0.0
    rig: PrismRig | None = None
    index: int = 0

    def bands(self, region: tuple[slice, slice]) -> Iterator[tuple[slice, np.ndarray,
                                                                    np.ndarray, np.ndarray]]:
        """Over a panorama ``region``, band by band of rows: (row slice relative to the region,
        map x, map y, lost) with the maps float32 view pixels and ``lost`` where no ray reaches
        the view (total reflection in a prism), or None."""
        rows = region[0].stop - region[0].start
        cols = region[1].stop - region[1].start
        m = self.to_frame
        pure_shift = np.allclose(m[:2, :2], np.eye(2), atol=0, rtol=0) and np.allclose(
            m[2], [0, 0, 1], atol=0, rtol=0)
        if self.rig is not None and pure_shift:
            origin = m[:2, 2] + [region[1].start, region[0].start]
            yield from _view_maps(self.rig, self.index, origin, (rows, cols), self.view_shape)
            return
        xs = np.arange(region[1].start, region[1].stop, dtype=np.float64)
        step = max(1, BAND_PIXELS // max(1, cols))
        for r0 in range(0, rows, step):
            band = slice(r0, min(r0 + step, rows))
            if self.rig is None and not self.k1:
                fx = np.empty((band.stop - band.start, cols), np.float32)
                fy = np.empty_like(fx)
                matrix_maps(np.ascontiguousarray(m, np.float64), float(region[1].start),
                            float(region[0].start + band.start), fx, fy)
                yield band, fx, fy, None
                continue
            ys = np.arange(region[0].start + band.start, region[0].start + band.stop,
                           dtype=np.float64)
            fx, fy = apply_matrix(m, xs[None, :], ys[:, None])
            lost = None
            if self.rig is not None:
                fx, fy = common_to_view(self.rig, self.index, fx, fy, self.view_shape)
                lost = ~(np.isfinite(fx) & np.isfinite(fy))
                fx, fy = np.where(lost, -10, fx), np.where(lost, -10, fy)
            elif self.k1:
                fx, fy = distort(fx, fy, self.k1, self.view_shape)
            yield band, fx.astype(np.float32), fy.astype(np.float32), lost

    def outline(self) -> np.ndarray:
        """(N, 2) panorama points (x, y) along the view's outline."""
        rows, cols = self.view_shape
        t = np.linspace(0.0, 1.0, 257)
        xs = np.concatenate([t * (cols - 1), np.full_like(t, cols - 1), t * (cols - 1),
                             np.zeros_like(t)])
        ys = np.concatenate([np.zeros_like(t), t * (rows - 1), np.full_like(t, rows - 1),
                             t * (rows - 1)])
        if self.rig is not None:
            xs, ys = view_to_common(self.rig, self.index, xs, ys, self.view_shape)
            ok = np.isfinite(xs) & np.isfinite(ys)
            xs, ys = xs[ok], ys[ok]
        px, py = apply_matrix(np.linalg.inv(self.to_frame), xs, ys)
        return np.stack([px, py], axis=1)


def apply_matrix(m: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (x, y) through the 3 x 3 matrix ``m`` (homogeneous, divided by w)."""
    w = m[2, 0] * x + m[2, 1] * y + m[2, 2]
    return (m[0, 0] * x + m[0, 1] * y + m[0, 2]) / w, (m[1, 0] * x + m[1, 1] * y + m[1, 2]) / w


def distort(x: np.ndarray, y: np.ndarray, k1: float, shape: tuple[int, int]):
    """Recorded pixel (x, y) of undistorted pixel (x, y) under ``r_d = r_u (1 + k1 r_u^2)``, r
    in half-diagonals from the image centre (the model of :func:`plenocli.stitch.views.undistort`).
    """
    rows, cols = shape
    cy, cx = (rows - 1) / 2, (cols - 1) / 2
    scale = 1.0 + k1 * ((x - cx) ** 2 + (y - cy) ** 2) / (cy * cy + cx * cx)
    return cx + (x - cx) * scale, cy + (y - cy) * scale


def resample(channels: np.ndarray, mx: np.ndarray, my: np.ndarray,
             interpolation: int = cv2.INTER_LANCZOS4) -> np.ndarray:
    """(C, h, w) float32: the view's channels (C, rows, cols; no NaN) at the maps (Lanczos-4,
    or ``interpolation``). Channels interleaved in memory (``np.moveaxis(rgb, -1, 0)`` of a
    (rows, cols, C) image) come out interleaved too."""
    rows, cols = channels.shape[1:]
    # pixels more than a pixel off the view are not covered whatever is resampled there:
    # pointing them 4 px inside (the 8 x 8 kernel's reach) keeps Lanczos-4 off its slow border
    # path
    off = (mx < -1) | (mx > cols) | (my < -1) | (my > rows)
    if off.any():
        mx, my = np.where(off, np.float32(4), mx), np.where(off, np.float32(4), my)
    pixels = np.moveaxis(channels, 0, -1)
    if 1 < len(channels) <= 4 and pixels.flags.c_contiguous:
        # channels interleaved in memory (a demosaiced view): one remap for all of them, each
        # pixel's kernel weights computed once (about 0.8 x the time of a remap per plane)
        out = cv2.remap(pixels, mx, my, interpolation, borderMode=cv2.BORDER_REPLICATE)
        return np.moveaxis(out, -1, 0)
    out = np.empty((len(channels),) + mx.shape, np.float32)
    for c, channel in enumerate(channels):
        out[c] = cv2.remap(channel, mx, my, interpolation, borderMode=cv2.BORDER_REPLICATE)
    return out


def feather(mx: np.ndarray, my: np.ndarray, shape: tuple[int, int], lost: np.ndarray | None,
            holes: tuple[np.ndarray, np.ndarray | None] | None) -> np.ndarray:
    """The view's feather weight at the maps, float32: its distance (view px) to the view's edge,
    or to its nearest hole when it has some (``holes`` = (valid as float32, distance map or
    None): :meth:`plenocli.stitch.nodata.NoData.holes`); 0 where the view does not fully cover
    the pixel (a no-data pixel's resampling footprint included)."""
    rows, cols = shape
    weight = np.empty(np.shape(mx), np.float32)
    # the distance to the edge is below 1 exactly where the source lies off the view; maps of
    # any shape (a band, or points), as rows of the compiled pass
    width = weight.shape[-1] if weight.ndim else 1
    if weight.size:
        edge_weight(np.asarray(mx, np.float32).reshape(-1, width),
                    np.asarray(my, np.float32).reshape(-1, width), rows, cols,
                    np.float32(1 - COVER_EPS_PX), weight.reshape(-1, width))
    if lost is not None:
        weight[lost] = 0
    if holes is not None:
        valid, distance = holes
        if distance is not None:
            np.minimum(weight, cv2.remap(distance, mx, my, cv2.INTER_LINEAR,
                                         borderMode=cv2.BORDER_REPLICATE), out=weight)
        weight[cv2.remap(valid, mx, my, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE) <= 0.999] = 0
    return weight
