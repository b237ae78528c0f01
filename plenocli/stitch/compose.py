"""Compositing: the panorama canvas, every view warped into it, exposure matched from the
overlaps, the canvas trimmed to what the views cover, and the seams blended (feathering or
Burt-Adelson multi-band)."""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from plenocli.errors import InputError
from plenocli.stitch.registration import difference_row
from plenocli.stitch.views import corners_xy, fill_nan_channels, translation_matrix


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


def _footprint(m: np.ndarray, shape: tuple[int, int], out_shape: tuple[int, int]):
    """The canvas box (row slice, column slice) a view of ``shape`` covers under ``m`` (view
    pixels -> canvas pixels), with 4 px for the resampling kernels, and ``m`` into that box."""
    pts = cv2.perspectiveTransform(corners_xy(shape), m).reshape(-1, 2)
    x0, y0 = (max(0, int(np.floor(v)) - 4) for v in pts.min(axis=0))
    x1 = min(out_shape[1], int(np.ceil(pts[:, 0].max())) + 5)
    y1 = min(out_shape[0], int(np.ceil(pts[:, 1].max())) + 5)
    x1, y1 = max(x1, x0 + 1), max(y1, y0 + 1)
    return (slice(y0, y1), slice(x0, x1)), translation_matrix(-y0, -x0) @ m


def _feather_weight(valid: np.ndarray) -> np.ndarray:
    """Distance (px) to the nearest invalid pixel or the view's border, float32."""
    if valid.all():  # the distance to the border, without a distance transform
        rows, cols = valid.shape
        to_y = np.minimum(np.arange(1, rows + 1), np.arange(rows, 0, -1)).astype(np.float32)
        to_x = np.minimum(np.arange(1, cols + 1), np.arange(cols, 0, -1)).astype(np.float32)
        return np.minimum(to_y[:, None], to_x[None, :])
    padded = np.pad(valid, 1)
    return ndimage.distance_transform_edt(padded)[1:-1, 1:-1].astype(np.float32)


def _warp(image: np.ndarray, m: np.ndarray, out_shape: tuple[int, int], *, interp: int,
          border: int = cv2.BORDER_REPLICATE) -> np.ndarray:
    size = (out_shape[1], out_shape[0])
    if np.allclose(m[2], [0, 0, 1]):
        return cv2.warpAffine(image, m[:2].astype(np.float64), size, flags=interp,
                              borderMode=border, borderValue=0)
    return cv2.warpPerspective(image, m, size, flags=interp, borderMode=border, borderValue=0)




def warp_views(stack: np.ndarray, transforms: list[np.ndarray], offset: np.ndarray,
               pano_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Every view (V, C, rows, cols) resampled onto the canvas (Lanczos-4; NaN outside its
    footprint) and its feather weight (distance to the view's edge, 0 outside)."""
    n_views, n_chan, rows, cols = stack.shape
    warped = np.full((n_views, n_chan) + pano_shape, np.nan, np.float32)
    weights = np.zeros((n_views,) + pano_shape, np.float32)
    for k in range(n_views):
        # each view is resampled only into its footprint on the canvas (the rest stays empty)
        box, m = _footprint(offset @ transforms[k], (rows, cols), pano_shape)
        box_shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
        valid = np.isfinite(stack[k]).all(axis=0)
        cover = _warp(valid.astype(np.float32), m, box_shape, interp=cv2.INTER_LINEAR,
                      border=cv2.BORDER_CONSTANT) > 0.999
        weights[k][box] = np.where(cover, _warp(_feather_weight(valid), m, box_shape,
                                                interp=cv2.INTER_LINEAR), 0)
        filled = fill_nan_channels(stack[k])
        for c in range(n_chan):
            img = _warp(filled[c], m, box_shape, interp=cv2.INTER_LANCZOS4)
            warped[k, c][box] = np.where(cover, img, np.nan)
    return warped, weights


def match_gains(warped: np.ndarray, weights: np.ndarray,
                pairs: list[tuple[int, int, str]]) -> np.ndarray:
    """Per-view, per-channel gains from overlap means (log least squares, view 0 fixed)."""
    n_views, n_chan = warped.shape[:2]
    gains = np.ones((n_views, n_chan))
    for c in range(n_chan):
        rows, rhs = [], []
        for a, b, _ in pairs:
            both = (weights[a] > 0) & (weights[b] > 0)
            both &= np.isfinite(warped[a, c]) & np.isfinite(warped[b, c])
            mean_a = float(warped[a, c][both].mean()) if both.any() else 0.0
            mean_b = float(warped[b, c][both].mean()) if both.any() else 0.0
            if mean_a <= 0 or mean_b <= 0:
                continue  # no usable overlap or signed data: leave this pair out
            rows.append(difference_row(a, b, n_views))
            rhs.append(np.log(mean_a / mean_b))
        if rows:
            sol, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
            gains[1:, c] = np.exp(sol)
    return gains


def trim_to_coverage(warped: np.ndarray, weights: np.ndarray, offset: np.ndarray):
    """The canvas cropped to what the views cover (rig canvases are generous): warped views,
    weights and the view-0 -> panorama translation, all of the cropped canvas."""
    covered = weights.sum(axis=0) > 0
    if not covered.any():
        return warped, weights, offset
    rows_any = np.flatnonzero(covered.any(axis=1))
    cols_any = np.flatnonzero(covered.any(axis=0))
    r0, r1, c0, c1 = rows_any[0], rows_any[-1] + 1, cols_any[0], cols_any[-1] + 1
    if (r0, c0, r1, c1) == (0, 0, *covered.shape):
        return warped, weights, offset
    offset = offset.copy()
    offset[0, 2] -= c0
    offset[1, 2] -= r0
    return warped[..., r0:r1, c0:c1], weights[:, r0:r1, c0:c1], offset


def blend(warped: np.ndarray, weights: np.ndarray, method: str) -> np.ndarray:
    """The panorama (C, rows, cols) float32 from the warped views (V, C, rows, cols) and their
    weights: feathering (weighted mean) or multi-band; NaN where no view covers it."""
    n_views, n_chan = warped.shape[:2]
    pano_shape = warped.shape[2:]
    total = weights.sum(axis=0)
    covered = total > 0
    panorama = np.full((n_chan,) + pano_shape, np.nan, np.float32)
    inv_total = 1.0 / np.maximum(total, 1e-12)
    for c in range(n_chan):
        # view by view: one canvas-sized temporary instead of a (views, canvas) stack
        feather = np.zeros(pano_shape, np.float32)
        for k in range(n_views):
            feather += np.nan_to_num(warped[k, c]) * weights[k]
        feather *= inv_total
        if method == "multiband":
            feather = _multiband(np.nan_to_num(warped[:, c]), weights, feather)
        panorama[c] = np.where(covered, feather, np.nan)
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


