"""Compiled (numba, ``nogil``) loops of the stitch's per-pixel work that numpy would do in many
passes over whole bands: the rig maps interpolated between node rows, and a view's weighted band
added into the panorama. Each does exactly the float operations of the numpy expressions it
replaces, in the same order (no fast-math), so the panorama is bit for bit the same; without
the GIL the main thread runs them while worker threads resample the next bands."""

from __future__ import annotations

import numba
import numpy as np


# explicit signatures: compiled once, into numba's cache, whatever views and bands a stitch
# passes. band_maps takes C-contiguous arrays (its callers' are): on row views its interpolation
# loop vectorises, 3 x faster than on arrays of any layout
@numba.njit("i8(f8[:, ::1], f8[:, ::1], i8[::1], f8[:, ::1], i8[::1], b1[:, ::1], f4[:, ::1], "
            "f4[:, ::1], b1[:, ::1])", cache=True, nogil=True, fastmath=False)
def band_maps(along_x: np.ndarray, along_y: np.ndarray, first_y: np.ndarray,
              weights_y: np.ndarray, first_x: np.ndarray, rough: np.ndarray,
              map_x: np.ndarray, map_y: np.ndarray, exact: np.ndarray) -> int:
    """The float32 remap maps of a band of rows: node rows ``along_x``/``along_y`` (node rows,
    cols; float64) interpolated by each row's 4-point stencil (``first_y`` first node,
    ``weights_y`` (rows, 4)); ``exact`` marks the pixels to trace instead (no value, or a
    ``rough`` cell (cells y, cells x) at (first_y, first_x)). Returns how many are marked."""
    count = 0
    for r in range(map_x.shape[0]):
        node = first_y[r]
        w0, w1, w2, w3 = weights_y[r, 0], weights_y[r, 1], weights_y[r, 2], weights_y[r, 3]
        x0, x1, x2, x3 = along_x[node], along_x[node + 1], along_x[node + 2], along_x[node + 3]
        y0, y1, y2, y3 = along_y[node], along_y[node + 1], along_y[node + 2], along_y[node + 3]
        mx, my, marked, rough_row = map_x[r], map_y[r], exact[r], rough[node]
        for c in range(map_x.shape[1]):
            vx = w0 * x0[c]
            vx += w1 * x1[c]
            vx += w2 * x2[c]
            vx += w3 * x3[c]
            vy = w0 * y0[c]
            vy += w1 * y1[c]
            vy += w2 * y2[c]
            vy += w3 * y3[c]
            mx[c] = np.float32(vx)
            my[c] = np.float32(vy)
            marked[c] = not (np.isfinite(vx) and np.isfinite(vy))
        for c in range(map_x.shape[1]):  # apart: its gather would keep the loop above scalar
            mark = marked[c] or rough_row[first_x[c]]
            marked[c] = mark
            count += mark
    return count


@numba.njit("void(f4[:, :, :], f4[:, :], f4[:, :, :], f4[:, :], f4[:], b1)", cache=True,
            nogil=True, fastmath=False)
def accumulate(sums: np.ndarray, total: np.ndarray, image: np.ndarray, weight: np.ndarray,
               gain: np.ndarray, scaled: bool) -> None:
    """``sums += image * gain * weight`` (channel by channel; the gain only when ``scaled``)
    and ``total += weight`` over a band, in float32 as the numpy expressions round. ``sums``
    need not be zeroed: where ``total`` is still 0 no weight was added, and it is set."""
    for r in range(weight.shape[0]):
        for c in range(weight.shape[1]):
            w = weight[r, c]
            first = total[r, c] == 0
            total[r, c] += w
            if w == 0:
                continue
            for k in range(image.shape[0]):
                v = image[k, r, c]
                if scaled:
                    v = v * gain[k]
                if first:
                    sums[k, r, c] = v * w
                else:
                    sums[k, r, c] += v * w


@numba.njit("void(f4[:, :, :], f4[:, :, :], f4[:, :, :], f4[:, :], f4[:, :, :], f4[:], b1, b1)",
            cache=True, nogil=True, fastmath=False)
def accumulate_channels(sums: np.ndarray, totals: np.ndarray, image: np.ndarray,
                        weight: np.ndarray, factor: np.ndarray, gain: np.ndarray, scaled: bool,
                        shared: bool) -> None:
    """:func:`accumulate` with a weight and a total per channel: ``sums[k] += image[k] * gain[k]
    * weight * factor[k]`` and ``totals[k] += weight * factor[k]`` (``factor`` read only unless
    ``shared``: a view that measured every channel, one weight for all)."""
    for r in range(weight.shape[0]):
        for c in range(weight.shape[1]):
            w = weight[r, c]
            if w == 0:
                continue
            for k in range(image.shape[0]):
                wk = w if shared else w * factor[k, r, c]
                first = totals[k, r, c] == 0
                totals[k, r, c] += wk
                v = image[k, r, c]
                if scaled:
                    v = v * gain[k]
                if first:
                    sums[k, r, c] = v * wk
                else:
                    sums[k, r, c] += v * wk


@numba.njit("void(f4[:, :, :], f4[:, :, :], b1[:, :])", cache=True, nogil=True, fastmath=False)
def normalise_channels(sums: np.ndarray, totals: np.ndarray, covered: np.ndarray) -> None:
    """:func:`normalise` with a total per channel (:func:`accumulate_channels`); a pixel is
    covered where its channels' totals are > 0 (all or none are: an estimate's share is > 0)."""
    tiny = np.float32(1e-12)
    for r in range(covered.shape[0]):
        for c in range(covered.shape[1]):
            covered[r, c] = totals[0, r, c] > 0
            for k in range(sums.shape[0]):
                t = totals[k, r, c]
                if t > 0:
                    sums[k, r, c] *= np.float32(1.0) / max(t, tiny)
                else:
                    sums[k, r, c] = np.nan


@numba.njit("void(f4[:, :, :], f4[:, :])", cache=True, nogil=True, fastmath=False)
def channel_mean(image: np.ndarray, out: np.ndarray) -> None:
    """``out`` = the mean of ``image``'s (C, rows, cols) channels, summed in order (any layout:
    interleaved RGB is read pixel by pixel); where a channel is NaN, the others' mean as
    ``np.nanmean`` gives it (NaN where every channel is)."""
    n = image.shape[0]
    scale = np.float32(1.0 / n)
    for r in range(out.shape[0]):
        for c in range(out.shape[1]):
            total = image[0, r, c]
            for k in range(1, n):
                total += image[k, r, c]
            if np.isnan(total):
                total = np.float32(0.0)
                count = 0
                for k in range(n):
                    v = image[k, r, c]
                    if not np.isnan(v):
                        total += v
                        count += 1
                out[r, c] = np.float32(np.float64(total) / count) if count else np.nan
            else:
                out[r, c] = total * scale


@numba.njit("void(f4[:, :, :], f4[:, :], b1[:, :])", cache=True, nogil=True, fastmath=False)
def normalise(sums: np.ndarray, total: np.ndarray, covered: np.ndarray) -> None:
    """A band's weighted sums divided by their weights (``sums *= 1 / max(total, 1e-12)`` in
    float32) where a view covers it (``total`` > 0, marked in ``covered``), NaN elsewhere: one
    pass instead of numpy's three."""
    tiny = np.float32(1e-12)
    for r in range(total.shape[0]):
        for c in range(total.shape[1]):
            t = total[r, c]
            covered[r, c] = t > 0
            if t > 0:
                inverse = np.float32(1.0) / max(t, tiny)
                for k in range(sums.shape[0]):
                    sums[k, r, c] *= inverse
            else:
                for k in range(sums.shape[0]):
                    sums[k, r, c] = np.nan


@numba.njit("void(f4[:, :], f4[:, :], i8, i8, f4, f4[:, :])", cache=True, nogil=True,
            fastmath=False)
def edge_weight(map_x: np.ndarray, map_y: np.ndarray, rows: int, cols: int, cut: np.float32,
                out: np.ndarray) -> None:
    """``out`` = a view's distance (view px) to its edge at the maps, ``min(x + 1, cols - x,
    y + 1, rows - y)`` rounded to float32 as numpy's float32 arithmetic rounds it, and 0 where
    that is below ``cut`` (the source off the view): one pass instead of numpy's six."""
    for r in range(out.shape[0]):
        for c in range(out.shape[1]):
            x, y = map_x[r, c], map_y[r, c]
            if np.isnan(x) or np.isnan(y):  # as np.minimum propagates it
                out[r, c] = np.nan
                continue
            w = np.float32(min(min(x + 1, cols - x), min(y + 1, rows - y)))
            out[r, c] = w if not w < cut else np.float32(0.0)


@numba.njit("void(f8[:, :], f8, f8, f4[:, :], f4[:, :])", cache=True, nogil=True,
            fastmath=False)
def matrix_maps(m: np.ndarray, x0: float, y0: float, map_x: np.ndarray,
                map_y: np.ndarray) -> None:
    """The float32 maps of a band of pixels (x0 + c, y0 + r) through the 3 x 3 matrix ``m``
    (homogeneous, divided by w): :func:`plenocli.stitch.warp.apply_matrix`'s float64
    operations in its order, then rounded, in one pass instead of numpy's ten."""
    for r in range(map_x.shape[0]):
        y = y0 + r
        for c in range(map_x.shape[1]):
            x = x0 + c
            w = m[2, 0] * x + m[2, 1] * y + m[2, 2]
            map_x[r, c] = (m[0, 0] * x + m[0, 1] * y + m[0, 2]) / w
            map_y[r, c] = (m[1, 0] * x + m[1, 1] * y + m[1, 2]) / w
