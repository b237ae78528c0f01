"""Demosaicing of Bayer views into full-resolution RGB, with clipped (NaN) pixels kept masked.

Methods (measured in docs/colour.md; the default is chosen there):

``opencv-ea``   OpenCV's edge-aware demosaicing (``COLOR_Bayer*2RGB_EA``), on 16-bit data
``opencv-vng``  OpenCV's variable number of gradients (8-bit only in OpenCV: quantised)
``malvar2004``  Malvar, He & Cutler 2004 (``colour-demosaicing``)
``menon2007``   Menon, Andriani & Calvagno 2007, DDFAPD with refining: colour-demosaicing's
                algorithm on OpenCV float32 filters (``plenocli.colour.menon``, 50 x faster,
                equal to the reference within float32 rounding: checked by the tests)
``bilinear``    bilinear interpolation (``colour-demosaicing``): the fast option
``rcd``         Ratio Corrected Demosaicing (RawTherapee's and darktable's default), in numba
                (``plenocli.colour.rcd``)

White balance comes first. Colour-difference and ratio demosaics assume that red, green and blue
of a grey surface are equal; in camera RGB they are not (a daylight Canon raw records red and
blue at about 0.45 and 0.8 of green), and interpolating across an edge then leaves zipper and
colour fringes. :func:`demosaic` therefore multiplies the mosaic by the white-balance gains,
demosaics, and divides the gains back out (camera RGB, what callers always got) unless asked for
the balanced result. Without gains it balances by the mosaic's own grey-edge estimate: any
roughly neutral balance serves the interpolation, and dividing it out again leaves no trace of
it in the colours.

NaN pixels (clipped or otherwise unknown) are filled from their valid neighbours of the same
colour before demosaicing, and afterwards every output pixel whose value can depend on a filled
pixel (within the method's support radius, measured by an impulse test in the test suite) is NaN
in all three channels: a clipped highlight stays masked instead of being smeared into its
neighbours.
"""

from __future__ import annotations

import os
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from plenocli.colour.menon import menon2007
from plenocli.colour.rcd import Workspace as RcdWorkspace
from plenocli.colour.rcd import rcd
from plenocli.model.colour import DEFAULT_METHOD, METHODS, normalised_gains  # noqa: F401

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
BAND_ROWS = 512  # rows demosaiced at a time: bounds the methods' scratch memory

# How far (pixels, Chebyshev) an input pixel can reach into the output, per method: the masks of
# NaN inputs are dilated by this much (tests/test_colour_demosaic.py checks each value).
SUPPORT_RADIUS = {"opencv-ea": 2, "opencv-vng": 2, "malvar2004": 2, "menon2007": 7,
                  "bilinear": 1, "rcd": 10}

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


def _output(out: np.ndarray | None, shape: tuple[int, int, int]) -> np.ndarray:
    if out is None:
        return np.empty(shape, np.float32)
    if out.shape != shape or out.dtype != np.float32:
        raise ValueError(f"out must be float32 {shape}, got {out.dtype} {out.shape}")
    return out


def demosaic(frame: np.ndarray, cfa: str, *, method: str = DEFAULT_METHOD, gains=None,
             balanced: bool = False, out: np.ndarray | None = None) -> np.ndarray:
    """Full-resolution RGB of a Bayer frame, demosaiced white-balanced.

    Parameters
    ----------
    frame : ndarray, (rows, cols)
        Linear mosaic above black (any unit, e.g. DN); NaN marks unknown (e.g. clipped) pixels.
    cfa : str
        2 x 2 pattern at pixel (0, 0): RGGB, BGGR, GRBG or GBRG.
    method : str
        One of :data:`METHODS`.
    gains : sequence of 3 floats, optional
        White-balance multipliers R, G, B (as shot, ``--wb``, ``--wb-from``); default: the
        mosaic's grey-edge estimate (:func:`grey_edge_gains`).
    balanced : bool
        Return the white-balanced RGB (times the gains) instead of camera RGB.
    out : ndarray float32, (rows, cols, 3), optional
        Written in place and returned (a view of a larger stack: no full-size copy).

    Returns
    -------
    ndarray float32, (rows, cols, 3)
        Camera RGB in the unit of ``frame`` (or balanced, see ``balanced``); NaN (all channels)
        wherever a NaN input pixel lies within the method's support radius.
    """
    pattern = check_pattern(cfa)
    if method not in METHODS:
        raise ValueError(f"method {method!r} unknown; choose one of {', '.join(METHODS)}")
    data = np.asarray(frame, np.float32)
    if data.ndim != 2 or data.shape[0] < 4 or data.shape[1] < 4:
        raise ValueError(f"frame must be a 2-D mosaic of at least 4 x 4 pixels, got {data.shape}")
    # one pass without a mask for the usual frame (an overflowing sum takes the masked way)
    has_unknown = not np.isfinite(np.sum(data))
    unknown = ~np.isfinite(data) if has_unknown else None
    if has_unknown:
        _check_every_site(unknown, pattern)
        data = fill_unknown(data, unknown)
    gains = grey_edge_gains(data, pattern) if gains is None else normalised_gains(gains)
    tile = np.array([gains["RGB".index(c)] for c in pattern], np.float32).reshape(2, 2)
    rgb = _output(out, (*data.shape, 3))
    radius = SUPPORT_RADIUS[method]
    margin = radius + radius % 2  # even: every band keeps the CFA phase of row 0
    low, high = (_balanced_range(data, tile) if method.startswith("opencv")
                 else (0.0, float(np.max(data)) * float(tile.max())))
    unbalance = np.ones(3, np.float32) if balanced else np.float32(1.0) / gains.astype(np.float32)
    local = threading.local()

    def one_band(start: int) -> None:
        stop = min(start + BAND_ROWS, data.shape[0])
        top, bottom = max(start - margin, 0), min(stop + margin, data.shape[0])
        if method == "rcd":  # balances and writes straight into rgb, gains divided out
            if not hasattr(local, "workspace"):
                local.workspace = RcdWorkspace(min(BAND_ROWS + 2 * margin, data.shape[0]),
                                               data.shape[1])
            rcd(data[top:bottom], pattern, scale=high, cfa_gains=tile, channel_scale=unbalance,
                out=rgb[start:stop], first_row=start - top, workspace=local.workspace)
            return
        band = data[top:bottom].copy()  # top is even: the band starts on the CFA's phase
        for k in range(4):
            band[k // 2::2, k % 2::2] *= tile[k // 2, k % 2]
        if method.startswith("opencv"):
            out = _demosaic_opencv(band, pattern, method, low, high)
        else:
            out = _demosaic_colour(band, pattern, method)
        rgb[start:stop] = out[start - top: start - top + stop - start]
        rgb[start:stop] *= unbalance

    # numba (nogil) and OpenCV release the GIL: bands on every core, each with its own scratch;
    # colour-demosaicing's functions run one band at a time (their warning filters are global)
    threaded = method in ("rcd", "menon2007", "opencv-ea", "opencv-vng")
    workers = (os.cpu_count() or 1) if threaded else 1
    with ThreadPoolExecutor(max_workers=workers) as pool:
        list(pool.map(one_band, range(0, data.shape[0], BAND_ROWS)))
    if has_unknown:
        kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
        reach = cv2.dilate(unknown.view(np.uint8), kernel).view(bool)
        rgb[reach] = np.nan
    return rgb


def _check_every_site(unknown: np.ndarray, pattern: str) -> None:
    """Refuse a mosaic in which one site of the 2 x 2 pattern (a whole colour plane, or one of
    the two greens) holds no known pixel: no neighbour of that colour is left to interpolate
    from, and rebuilt from the other colours it would be invented (the frame's median, then
    the clipped-highlight estimate)."""
    if unknown.all():
        raise ValueError("frame has no finite pixel to demosaic")
    for k, colour in enumerate(pattern):
        if unknown[k // 2::2, k % 2::2].all():
            site = f"{colour} ({'first' if pattern.index(colour) == k else 'second'} green) " \
                if colour == "G" else f"{colour} "
            raise ValueError(f"no {site}pixel of the {pattern} mosaic is known (all NaN: "
                             "clipped or masked), so its colour cannot be rebuilt from the "
                             "others; demosaic a frame that recorded it (check the flat-field "
                             "or the masking that emptied it)")


def grey_edge_gains(frame: np.ndarray, cfa: str) -> np.ndarray:
    """Gains (R, G, B; green 1) that make the mean absolute gradient of each colour of a mosaic
    equal to green's: the grey-edge estimate (van de Weijer, Gevers & Gijsenij 2007; edges of
    natural scenes average to grey far more reliably than their colours do). Gradients between
    neighbours of the same colour, on every fourth row of each colour plane; 1 for a colour
    without any."""
    pattern = check_pattern(cfa)
    edges = np.zeros(3)
    for k, colour in enumerate(pattern):
        plane = np.asarray(frame, np.float32)[k // 2::2, k % 2::2]
        rows = plane.shape[0] // 4 * 4 or plane.shape[0]
        across = np.abs(np.diff(plane[:rows:4], axis=1))
        down = np.abs(plane[1:rows:4] - plane[0:rows - 1:4]) if rows > 1 else across[:0]
        values = np.concatenate([across.ravel(), down.ravel()])
        values = values[np.isfinite(values)]
        edges["RGB".index(colour)] += (values.mean() if values.size else 0.0) / pattern.count(
            colour)
    if edges[1] <= 0 or not np.all(np.isfinite(edges)):
        return np.ones(3)
    gains = np.where(edges > 0, edges[1] / np.where(edges > 0, edges, 1.0), 1.0)
    return np.clip(gains, 0.1, 10.0)  # a flat plane says nothing: no light source is beyond


def _balanced_range(data: np.ndarray, tile: np.ndarray) -> tuple[float, float]:
    """The smallest and largest value of the balanced mosaic (without making it)."""
    low, high = np.inf, -np.inf
    for k in range(4):
        plane = data[k // 2::2, k % 2::2]
        gain = float(tile[k // 2, k % 2])
        low, high = min(low, float(plane.min()) * gain), max(high, float(plane.max()) * gain)
    return low, high


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
            if missing.all():  # nothing of this colour to grow from (demosaic refuses it)
                raise ValueError("a site of the mosaic has no known pixel to fill from")
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
