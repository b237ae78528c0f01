"""The view stack: validation, a known radial distortion removed, and the high-passed texture the
registration works on.

Geometry convention of the whole package: a transform is a 3 x 3 matrix mapping a view's pixel
``(x, y, 1)`` (column, row) to the pixel coordinates of view 0 (the reference). Views are ordered
row-major over the layout: ``1x2`` = left, right; ``2x1`` = top, bottom; ``2x2`` = S00, S01, S10,
S11 (top-left, top-right, bottom-left, bottom-right).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np
from scipy import ndimage

from plenocli.stitch.errors import StitchError
from plenocli.stitch.kernels import channel_mean

LAYOUTS = {"1x2": (1, 2), "2x1": (2, 1), "2x2": (2, 2)}
VIEW_NAMES = {"1x2": ("L", "R"), "2x1": ("T", "B"), "2x2": ("S00", "S01", "S10", "S11")}
# views named as a layout's places say where they lie (left.tif and right.tif, refocus's
# views, are named after their files)
_NAMED_PLACES = {**VIEW_NAMES, "left,right": ("left", "right"), "top,bottom": ("top", "bottom")}
MODELS = ("translation", "homography")
BLENDS = ("feather", "multiband")
HIGHPASS_SIGMA_PX = 8.0


def neighbour_pairs(layout: str) -> list[tuple[int, int, str]]:
    """Neighbour pairs (a, b, direction): 'h' = b right of a, 'v' = b below a."""
    return {"1x2": [(0, 1, "h")], "2x1": [(0, 1, "v")],
            "2x2": [(0, 1, "h"), (0, 2, "v"), (1, 3, "v"), (2, 3, "h")]}[layout]


def translation_matrix(dy: float, dx: float) -> np.ndarray:
    """The 3 x 3 matrix of the shift (dy, dx) px."""
    m = np.eye(3)
    m[0, 2], m[1, 2] = dx, dy
    return m


def as_view_stack(views: np.ndarray | Sequence[np.ndarray]) -> tuple[np.ndarray, bool]:
    """Validate views and return them as (V, C, rows, cols) float32 plus ``colour`` (C given).

    ``views`` is (V, rows, cols), (V, C, rows, cols) or a sequence of equally shaped arrays.
    Views of different sizes or channel counts are rejected (crop or resample them first).
    """
    if isinstance(views, np.ndarray):
        arrays = list(views)
    else:
        arrays = [np.asarray(v) for v in views]
    if len(arrays) not in (2, 4):
        raise StitchError(f"stitch needs 2 or 4 views, got {len(arrays)}; select views with "
                         "--views (e.g. --views A,B)")
    first = arrays[0].shape
    for k, a in enumerate(arrays):
        if a.ndim not in (2, 3):
            raise StitchError(f"view {k} has shape {a.shape}; a view is (rows, cols) or "
                             "(channels, rows, cols)")
        if a.shape != first:
            what = "channel count" if a.ndim != len(first) or a.shape[-2:] == first[-2:] else "size"
            raise StitchError(f"view {k} has shape {a.shape} but view 0 has {first} (different "
                             f"{what}); stitch needs views of one size and one channel count")
    colour = len(first) == 3
    if isinstance(views, np.ndarray) and views.dtype == np.float32:
        stack = views if colour else views[:, np.newaxis]  # read only: no copy of the caller's
    else:
        stack = np.empty((len(arrays),) + (first if colour else (1,) + first), np.float32)
        for k, a in enumerate(arrays):
            stack[k] = a
    if min(stack.shape[-2:]) < 32:
        raise StitchError(f"views of {stack.shape[-1]} x {stack.shape[-2]} px (columns x rows) "
                         "are too small to register; need at least 32 x 32")
    return stack, colour


def luminance(stack: np.ndarray) -> np.ndarray:
    """(V, rows, cols): the channel mean of a (V, C, rows, cols) stack (NaN where no channel has
    data), scaled to unit level (:func:`unit_level`), what the registration works on.
    Refuses a view without data or without texture."""
    n_views, n_chan, rows, cols = stack.shape
    if n_chan > 1:
        luma = np.empty((n_views, rows, cols), np.float32)
        # compiled, without the GIL: the views at once
        with ThreadPoolExecutor(max_workers=min(n_views, os.cpu_count() or 1)) as pool:
            list(pool.map(channel_mean, stack, luma))
    else:
        luma = stack[:, 0]
    for k in range(len(luma)):
        lo, hi = np.fmin.reduce(luma[k], axis=None), np.fmax.reduce(luma[k], axis=None)
        if not np.isfinite(hi):
            raise StitchError(f"view {k} holds no data (all NaN)")
        if lo == hi:
            raise StitchError(f"view {k} has no texture (constant image); stitching needs "
                             "structure in the overlap")
    return unit_level(luma, copied=n_chan > 1)


# pixels sampled for a view's level: a median of |value| needs no precision
LEVEL_SAMPLE_PX = 1 << 16


def level(view: np.ndarray) -> float:
    """A view's level: the median |value| of its finite pixels (sampled), else its largest
    |value| (a view mostly 0); 0 for a view of zeros or without data."""
    step_px = max(1, int(np.sqrt(view.size / LEVEL_SAMPLE_PX)))
    sample = np.abs(view[::step_px, ::step_px].astype(np.float64))
    sample = sample[np.isfinite(sample)]
    found = float(np.median(sample)) if sample.size else 0.0
    if found > 0:
        return found
    ends = (float(np.fmin.reduce(view, axis=None)), float(np.fmax.reduce(view, axis=None)))
    return max(abs(e) for e in ends) if all(np.isfinite(ends)) else 0.0


def unit_level(luma: np.ndarray, *, copied: bool = False) -> np.ndarray:
    """The views (V, rows, cols) multiplied by the one power of two that brings their level
    (the median of the views' :func:`level`) into [0.5, 1): exact, and the registration sees
    the views at the scale its thresholds were set on, so their unit does not move the match
    (float32's floors and the fits' tolerances are absolute). One factor for all (each pair
    is then matched at its two views' own levels: :func:`at_own_level`). ``copied``:
    ``luma`` is the caller's own and may be scaled in place."""
    exponent = int(np.frexp(float(np.median([level(v) for v in luma])))[1])
    if not exponent:
        return luma
    out = luma if copied else np.empty(luma.shape, np.float32)
    factor = np.ldexp(np.float32(1.0), -exponent)  # a float32 power of two: exact products
    for k, view in enumerate(luma):  # view by view: no float64 copy of the stack
        if 0 < factor < np.inf:  # a product, 6 x faster than numpy's ldexp
            np.multiply(view, factor, out=out[k])
        else:
            out[k] = np.ldexp(view, -exponent)
    return out


def at_own_level(*views: np.ndarray) -> list[np.ndarray]:
    """Each view divided by its :func:`level` (float32), for the sub-pixel fits of a pair: their
    photometric model and floors then see two views of one level whatever their exposures."""
    out = []
    for view in views:
        found = level(view)
        out.append(np.asarray(view, np.float32) if not 0 < found < np.inf
                   else (view / np.float32(found)).astype(np.float32))
    return out


def undistort(image: np.ndarray, k1: float) -> np.ndarray:
    """Remove a constant radial distortion ``r_d = r_u (1 + k1 r_u^2)`` from a (rows, cols) image.

    ``r`` is measured from the image centre in units of the half-diagonal, so ``k1 = 0.01`` moves
    the corners outward by 1 %. Resampled with Lanczos-4; NaN stays NaN (within the kernel).
    """
    if not (np.isfinite(k1) and -1 < k1 <= 1):
        raise ValueError(f"distortion k1 must be a finite number in (-1, 1], got {k1}")
    if k1 == 0:
        return image
    rows, cols = image.shape
    cy, cx = (rows - 1) / 2, (cols - 1) / 2
    norm = np.hypot(cy, cx)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float32)
    ru2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / norm**2
    scale = 1.0 + k1 * ru2
    map_x = (cx + (xx - cx) * scale).astype(np.float32)
    map_y = (cy + (yy - cy) * scale).astype(np.float32)
    return cv2.remap(image.astype(np.float32), map_x, map_y, cv2.INTER_LANCZOS4,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan)


def fill_nan(image: np.ndarray) -> np.ndarray:
    """NaN replaced by the nearest finite value (so the resampling kernel does not spread NaN)."""
    bad = ~np.isfinite(image)
    if not bad.any():
        return image
    if bad.all():
        return np.zeros_like(image)
    idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
    return image[tuple(idx)]


def fill_nan_channels(channels: np.ndarray, *, in_place: bool = False) -> np.ndarray:
    """:func:`fill_nan` of every channel of (C, rows, cols); channels with the same NaN pixels
    (a demosaiced view, a rig canvas) share one distance transform. ``in_place``: fill
    ``channels`` itself (no copy) and return it."""
    bad = ~np.isfinite(channels)
    if not bad.any():
        return channels
    out = channels if in_place else np.empty_like(channels)
    if not (bad == bad[0]).all():
        for c in range(len(channels)):
            out[c] = fill_nan(channels[c])
        return out
    if bad[0].all():
        out[...] = 0
        return out
    rows, cols = ndimage.distance_transform_edt(bad[0], return_distances=False,
                                                return_indices=True)
    del bad
    for c in range(len(channels)):
        out[c] = channels[c][rows, cols]
    return out


def highpass(image: np.ndarray) -> np.ndarray:
    """Texture only: image minus a wide Gaussian blur, float32 (removes vignetting and offsets).

    With NaN (no data) the blur is a normalised convolution over the valid pixels and the
    result is 0 where there is no data, so the edges of a view's data add no false texture.
    """
    valid = np.isfinite(image)
    if valid.all():
        img = image.astype(np.float32)
        return img - cv2.GaussianBlur(img, (0, 0), HIGHPASS_SIGMA_PX)
    m = valid.astype(np.float32)
    img = np.where(valid, image, 0).astype(np.float32)
    blur = cv2.GaussianBlur(img, (0, 0), HIGHPASS_SIGMA_PX) / np.maximum(
        cv2.GaussianBlur(m, (0, 0), HIGHPASS_SIGMA_PX), 1e-6)
    return np.where(valid, img - blur, 0).astype(np.float32)


def erode(mask: np.ndarray, iterations: int, *, outside: bool = False) -> np.ndarray:
    """``scipy.ndimage.binary_erosion(mask, iterations=..., border_value=outside)`` (the
    4-neighbour cross; ``outside``: whether the pixels beyond the array count as True), by
    OpenCV: the same pixels, ten times faster."""
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    return cv2.erode(np.ascontiguousarray(mask).view(np.uint8), cross, iterations=iterations,
                     borderType=cv2.BORDER_CONSTANT, borderValue=int(outside)).view(bool)


def valid_eroded(view: np.ndarray) -> np.ndarray:
    """Pixels with data, eroded by 2 px (the view's border counts as no data)."""
    finite = np.isfinite(view)
    if not finite.all():
        return erode(finite, 2)
    finite[:2], finite[-2:], finite[:, :2], finite[:, -2:] = False, False, False, False
    return finite


def corners_xy(shape: tuple[int, int]) -> np.ndarray:
    """(4, 1, 2) float64 corners (x, y) of a (rows, cols) view, for cv2.perspectiveTransform."""
    rows, cols = shape
    return np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]]).reshape(
        -1, 1, 2)


def layout_of_names(names: list[str], layout: str) -> str:
    """The layout the views' names give (``layout`` when they name none). Views named a
    layout's places in another order, or a ``layout`` other than "auto" that contradicts
    them, are refused (StitchError): registered as given, the stereo rig's R, L (or a left.tif
    given after right.tif) was matched one above the other on chance or ghost texture and
    written (correlation 0.45, residual 0.25 px)."""
    for key, places in _NAMED_PLACES.items():
        if sorted(names) != sorted(places):
            continue
        named = "1x2" if key in ("left,right", "1x2") else "2x1" if key == "top,bottom" else key
        if list(names) != list(places):
            raise StitchError(f"the views are named {','.join(names)}: their names place them "
                              f"as {','.join(places)} (layout {named}); list them in that order "
                              f"(--views {','.join(places)}, or the files in that order)")
        if layout not in ("auto", named):
            raise StitchError(f"--layout {layout} contradicts the views' names "
                              f"{','.join(names)} (layout {named}); drop --layout")
        return named
    return layout
