"""Flattening: divide out vignetting, colour balance and scene brightness; the micro-lens
pattern (periods shorter than the blur) stays. Also the border signal (gradient magnitude) and
the decimation used to look at large pitches."""

from __future__ import annotations

import cv2
import numpy as np


def flatten(image: np.ndarray, *, cfa: str | None = None, scale_px: float = 64.0) -> np.ndarray:
    """Divide each CFA plane by its blurred self: vignetting, colour balance and scene
    brightness go, the micro-lens pattern (periods < ``scale_px``) stays.

    Parameters
    ----------
    image : (rows, cols) array, any real dtype
    cfa : 2 x 2 Bayer pattern at pixel (0, 0), or None for mono / one colour plane
    scale_px : Gaussian sigma of the blur, in pixels of ``image``

    Returns
    -------
    (rows, cols) float32, about 1 on average, clipped to [0, 4].
    """
    if image.ndim != 2:
        raise ValueError(f"image must be 2-D, got shape {image.shape}")
    step = 2 if cfa else 1
    out = np.empty(image.shape, np.float32)
    for r in range(step):
        for c in range(step):
            plane = np.asarray(image[r::step, c::step], dtype=np.float32)
            np.divide(plane, _blur(plane, scale_px / step), out=out[r::step, c::step])
    finite = np.isfinite(out)
    if not finite.all():
        out[~finite] = 0.0
    np.clip(out, 0.0, 4.0, out=out)
    return out


def _blur(plane: np.ndarray, sigma: float) -> np.ndarray:
    """Large Gaussian-weighted local *linear* fit done on a shrunk copy (fast), floored to stay
    positive. Inside the frame it is the Gaussian blur; near the border a plain blur (any
    padding) flattens the vignetting slope and tilts the border micro-images, the local linear
    fit keeps the slope."""
    rows, cols = plane.shape
    factor = max(1, min(int(sigma // 4), rows // 8, cols // 8))
    small = cv2.resize(plane, (max(1, cols // factor), max(1, rows // factor)),
                       interpolation=cv2.INTER_AREA) if factor > 1 else plane
    level = float(np.mean(small))    # a constant is fitted exactly: keep rounding off it
    fit = small.astype(np.float64) - level
    for axis in (0, 1):
        fit = _local_linear_1d(fit, sigma / factor, axis)
    fit = (fit + level).astype(np.float32)
    blurred = cv2.resize(fit, (cols, rows), interpolation=cv2.INTER_LINEAR) \
        if factor > 1 else fit
    floor = max(float(np.mean(blurred)) * 1e-3, 1e-12)
    return np.maximum(blurred, np.float32(floor), out=blurred)


def _local_linear_1d(f: np.ndarray, sigma: float, axis: int) -> np.ndarray:
    """Gaussian-weighted local linear fit along ``axis`` of a float64 image, over the frame only
    (no padding): the value at t of the line fitted to f(t') with weights g(t' - t)."""
    n = f.shape[axis]
    half = int(np.ceil(3 * sigma))
    kern = cv2.getGaussianKernel(2 * half + 1, sigma)[:, 0]
    t = np.arange(n, dtype=np.float64) - n / 2

    def g1d(a):   # the truncated sums along the line, (n,)
        return np.convolve(a, kern)[half:half + n]

    g0, g1, g2 = g1d(np.ones(n)), g1d(t), g1d(t * t)
    m1 = g1 - t * g0                       # moments of (t' - t)
    m2 = g2 - 2 * t * g1 + t * t * g0
    det = g0 * m2 - m1 * m1
    shape = (n, 1) if axis == 0 else (1, n)
    ca = (m2 / det).reshape(shape)   # a = ca G(f) + cb (G(t f) - t G(f))
    cb = (-m1 / det).reshape(shape)
    t_img = t.reshape(shape)
    one = np.ones((1, 1))
    kx, ky = (one, kern[:, None]) if axis == 0 else (kern[:, None], one)

    def g(a):
        return cv2.sepFilter2D(a, cv2.CV_64F, kx, ky, borderType=cv2.BORDER_CONSTANT)

    gf = g(f)
    return ca * gf + cb * (g(f * t_img) - t_img * gf)


def border_signal(flat: np.ndarray) -> np.ndarray:
    """|grad| of a flattened image (central differences), clipped at its 99th percentile: the
    micro-image borders are edges in every lenslet image, whatever the scene; a few strong
    scene edges must not dominate."""
    grad = cv2.Sobel(flat, cv2.CV_32F, 1, 0, ksize=1)
    gy = cv2.Sobel(flat, cv2.CV_32F, 0, 1, ksize=1)
    grad *= grad   # in place: a view's signals are built side by side
    gy *= gy
    grad += gy
    del gy
    np.sqrt(grad, out=grad)
    return np.minimum(grad, np.float32(np.percentile(grad[::3, ::3], 99)), out=grad)


def decimate(image: np.ndarray, factor: int) -> np.ndarray:
    """Area-average ``image`` by an integer ``factor`` (float32)."""
    image = np.asarray(image, np.float32)
    if factor <= 1:
        return image
    rows, cols = image.shape
    return cv2.resize(image, (cols // factor, rows // factor), interpolation=cv2.INTER_AREA)
