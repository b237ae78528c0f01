"""Demosaicing of Bayer views into full-resolution RGB, with clipped (NaN) pixels kept masked.

Methods (measured in docs/colour.md; the default is chosen there):

``opencv-ea``   OpenCV's edge-aware demosaicing (``COLOR_Bayer*2RGB_EA``), on 16-bit data
``opencv-vng``  OpenCV's variable number of gradients (8-bit only in OpenCV: quantised)
``malvar2004``  Malvar, He & Cutler 2004 (``colour-demosaicing``)
``menon2007``   Menon, Andriani & Calvagno 2007, DDFAPD with refining: colour-demosaicing's
                algorithm on OpenCV float32 filters (``plenocli.colour.menon``, 50 x faster,
                equal to the reference within float32 rounding: checked by the tests)
``bilinear``    bilinear interpolation (``colour-demosaicing``): the fast option

NaN pixels (clipped or otherwise unknown) are filled from their valid neighbours of the same
colour before demosaicing, and afterwards every output pixel whose value can depend on a filled
pixel (within the method's support radius, measured by an impulse test in the test suite) is NaN
in all three channels: a clipped highlight stays masked instead of being smeared into its
neighbours.
"""

from __future__ import annotations

import warnings

import cv2
import numpy as np

from plenocli.colour.menon import menon2007

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
METHODS = ("opencv-ea", "opencv-vng", "malvar2004", "menon2007", "bilinear")
DEFAULT_METHOD = "menon2007"  # best PSNR and dE2000 measured (docs/colour.md)
BAND_ROWS = 512  # rows demosaiced at a time: bounds the methods' scratch memory

# How far (pixels, Chebyshev) an input pixel can reach into the output, per method: the masks of
# NaN inputs are dilated by this much (tests/test_colour_demosaic.py checks each value).
SUPPORT_RADIUS = {"opencv-ea": 2, "opencv-vng": 2, "malvar2004": 2, "menon2007": 7,
                  "bilinear": 1}

_OPENCV_CODES = {
    ("opencv-ea", p): getattr(cv2, f"COLOR_Bayer{p}2RGB_EA") for p in BAYER_PATTERNS
} | {("opencv-vng", p): getattr(cv2, f"COLOR_Bayer{p}2RGB_VNG") for p in BAYER_PATTERNS}


def check_pattern(cfa: str | None) -> str:
    """The 2 x 2 Bayer pattern in upper case, or ValueError naming what is wrong."""
    if cfa is None:
        raise ValueError("cfa is None: the data has no colour filter array (a mono capture); "
                         "colour needs a Bayer capture")
    pattern = str(cfa).upper()
    if pattern not in BAYER_PATTERNS:
        raise ValueError(f"cfa {cfa!r} is not a 2 x 2 Bayer pattern plenocli can demosaic "
                         f"(one of {', '.join(BAYER_PATTERNS)})")
    return pattern


def mosaic(rgb: np.ndarray, cfa: str) -> np.ndarray:
    """The Bayer mosaic (rows, cols) a sensor with pattern ``cfa`` records of ``rgb`` (rows,
    cols, 3): each pixel keeps the one channel its filter passes."""
    pattern = check_pattern(cfa)
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[-1] != 3:
        raise ValueError(f"rgb must be (rows, cols, 3), got shape {rgb.shape}")
    out = np.empty(rgb.shape[:2], rgb.dtype)
    for k, colour in enumerate(pattern):
        out[k // 2::2, k % 2::2] = rgb[k // 2::2, k % 2::2, "RGB".index(colour)]
    return out


def demosaic(frame: np.ndarray, cfa: str, *, method: str = DEFAULT_METHOD) -> np.ndarray:
    """Full-resolution RGB of a Bayer frame.

    Parameters
    ----------
    frame : ndarray, (rows, cols)
        Linear mosaic (any unit, e.g. DN above black); NaN marks unknown pixels.
    cfa : str
        2 x 2 pattern at pixel (0, 0): RGGB, BGGR, GRBG or GBRG.
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    ndarray float32, (rows, cols, 3)
        RGB in the unit of ``frame``; NaN (all channels) wherever a NaN input pixel lies within
        the method's support radius.
    """
    pattern = check_pattern(cfa)
    if method not in METHODS:
        raise ValueError(f"method {method!r} unknown; choose one of {', '.join(METHODS)}")
    data = np.asarray(frame, np.float32)
    if data.ndim != 2 or data.shape[0] < 4 or data.shape[1] < 4:
        raise ValueError(f"frame must be a 2-D mosaic of at least 4 x 4 pixels, got {data.shape}")
    unknown = ~np.isfinite(data)
    has_unknown = bool(unknown.any())
    if has_unknown:
        if unknown.all():
            raise ValueError("frame has no finite pixel to demosaic")
        data = fill_unknown(data, unknown)
    rgb = np.empty((*data.shape, 3), np.float32)
    radius = SUPPORT_RADIUS[method]
    margin = radius + radius % 2  # even: every band keeps the CFA phase of row 0
    low, high = float(data.min()), float(data.max())
    for start in range(0, data.shape[0], BAND_ROWS):
        stop = min(start + BAND_ROWS, data.shape[0])
        top, bottom = max(start - margin, 0), min(stop + margin, data.shape[0])
        band = data[top:bottom]
        if method.startswith("opencv"):
            out = _demosaic_opencv(band, pattern, method, low, high)
        else:
            out = _demosaic_colour(band, pattern, method)
        rgb[start:stop] = out[start - top: start - top + stop - start]
    if has_unknown:
        kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
        reach = cv2.dilate(unknown.view(np.uint8), kernel).view(bool)
        rgb[reach] = np.nan
    return rgb


def fill_unknown(frame: np.ndarray, unknown: np.ndarray) -> np.ndarray:
    """A copy of a mosaic with its unknown pixels replaced by the mean of the nearest known
    pixels of the same colour (growing 3 x 3 neighbourhoods of the colour plane), so that the
    demosaicing filters see plausible values; the caller masks what they reach afterwards."""
    out = frame.copy()
    for r in range(2):
        for c in range(2):
            plane = out[r::2, c::2]  # a view: filling it fills ``out``
            missing = unknown[r::2, c::2].copy()
            if not missing.any():
                continue
            if missing.all():
                plane[...] = float(np.nanmedian(frame[np.isfinite(frame)]))
                continue
            value = np.where(missing, 0.0, plane).astype(np.float32)
            weight = (~missing).astype(np.float32)
            while missing.any():
                total = cv2.boxFilter(value, -1, (3, 3), normalize=False,
                                      borderType=cv2.BORDER_REFLECT)
                count = cv2.boxFilter(weight, -1, (3, 3), normalize=False,
                                      borderType=cv2.BORDER_REFLECT)
                reached = missing & (count > 0)
                value[reached] = total[reached] / count[reached]
                weight[reached] = 1.0
                missing &= ~reached
            plane[...] = value
    return out


def _demosaic_opencv(data: np.ndarray, pattern: str, method: str, low: float,
                     high: float) -> np.ndarray:
    """OpenCV works on integers: scale [low, high] to the 16-bit (EA) or 8-bit (VNG) range."""
    span = max(high - low, 1e-30)
    top = 65535.0 if method == "opencv-ea" else 255.0
    dtype = np.uint16 if method == "opencv-ea" else np.uint8
    scaled = np.empty(data.shape, dtype)
    np.rint((data - low) * (top / span), out=scaled, casting="unsafe")
    rgb = cv2.cvtColor(scaled, _OPENCV_CODES[(method, pattern)])
    out = rgb.astype(np.float32)
    out *= np.float32(span / top)
    out += np.float32(low)
    return out


def _demosaic_colour(data: np.ndarray, pattern: str, method: str) -> np.ndarray:
    if method == "menon2007":  # ours: no colour-science import (1.5 s) for the default
        return menon2007(data, pattern)
    with warnings.catch_warnings():  # colour-science warns about optional plotting packages
        warnings.simplefilter("ignore")
        import colour_demosaicing as cd

    function = {"malvar2004": cd.demosaicing_CFA_Bayer_Malvar2004,
                "bilinear": cd.demosaicing_CFA_Bayer_bilinear}[method]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(function(data, pattern), np.float32)
