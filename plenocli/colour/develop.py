"""Developing views into colour images: which pages form a colour view, then white balance and
demosaic (the mosaic is balanced before it is interpolated), the camera matrix
(scene-referred), then scaling and a display space (output-referred).

A views file holds colour in one of three ways (its metadata says which):

- Bayer mosaics: ``cfa`` (every page) or ``view_colours`` (a 2 x 2 pattern per page, e.g. the
  half-resolution mosaic of each quad-Bayer SAI);
- RGB triplets: pages named ``R, G, B`` or ``NAME.R, NAME.G, NAME.B`` (a refocus sweep's
  ``R@g4, G@g4, B@g4`` is view ``RGB@g4``);
- anything else is monochrome, and asking it for colour is an error.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from plenocli.colour.balance import normalised_gains
from plenocli.colour.demosaic import DEFAULT_METHOD, check_pattern, demosaic, grey_edge_gains
from plenocli.colour.highlights import Estimated, rebuild_partly_clipped
from plenocli.io.photo import encode
from plenocli.model.colour import srgb_to_space
from plenocli.model.views import CHANNELS, split_colour_page, split_sweep

BAND_ROWS = 256  # rows per matrix product: bounds the temporaries to a few MB per band


@dataclass(frozen=True)
class ColourView:
    """One colour view of a views file: its name, the pages it is made of, and its CFA pattern
    (None when the pages already are R, G, B)."""

    name: str
    pages: tuple[int, ...]
    cfa: str | None


def colour_views(names: list[str], *, cfa: str | None = None,
                 view_colours: list | None = None) -> list[ColourView]:
    """The colour views of a views file, from its page names and CFA metadata.

    Raises ValueError (one line, what to do) for monochrome data, an unknown CFA, or views that
    each hold a single colour.
    """
    if view_colours and any(c is not None for c in view_colours):
        if len(view_colours) != len(names):
            raise ValueError(f"{len(view_colours)} view colours for {len(names)} views")
        if all(c is not None and len(str(c)) == 1 for c in view_colours):
            raise ValueError("each view holds a single colour (SAIs of a per-pixel Bayer "
                             "sensor); no view can be made colour on its own")
        return [ColourView(n, (k,), check_pattern(c)) for k, (n, c)
                in enumerate(zip(names, view_colours, strict=True))]
    if cfa:
        pattern = check_pattern(cfa)
        return [ColourView(n, (k,), pattern) for k, n in enumerate(names)]
    by_view: dict[str, dict[str, int]] = {}
    for k, name in enumerate(names):
        label, tag = split_sweep(name)  # refocus sweeps: R@g4, left.R@g4, ...
        split = ("", label) if label in CHANNELS else split_colour_page(label)
        if split is None:  # a page of no colour: the views carry none
            by_view = {}
            break
        by_view.setdefault((split[0] or "RGB") + tag, {})[split[1]] = k
    if by_view and all(set(ch) == set(CHANNELS) for ch in by_view.values()):
        return [ColourView(view, tuple(ch[c] for c in CHANNELS), None)
                for view, ch in by_view.items()]
    raise ValueError(f"views {', '.join(names)} carry no colour (no CFA pattern and no R, G, B "
                     "pages): a monochrome capture cannot be developed in colour")


def camera_rgb(pages: np.ndarray, view: ColourView, *, method: str = DEFAULT_METHOD,
               gains=None, out: np.ndarray | None = None,
               estimated: Estimated | None = None) -> np.ndarray:
    """Camera RGB (rows, cols, 3) float32 of one colour view; a Bayer view is demosaiced
    white-balanced by ``gains`` (the ones the photograph is developed with; None: the mosaic's
    own estimate), see :func:`plenocli.colour.demosaic.demosaic`. Pixels clipped in some
    channels only are rebuilt (:func:`plenocli.colour.highlights.rebuild_partly_clipped`);
    those clipped in every channel stay NaN; ``estimated`` (:class:`Estimated`) is told which
    channels of which pixels that rebuild estimated. ``out`` (rows, cols, 3) float32: written
    in place and returned."""
    _check_scalable(pages, view.pages)
    if view.cfa is None:
        rgb = np.stack([np.asarray(pages[k], np.float32) for k in view.pages], axis=-1)
        if out is None:
            return rgb
        out[...] = rgb
        return out
    frame = pages[view.pages[0]]
    if gains is None:
        gains = grey_edge_gains(frame, view.cfa)
    rgb = demosaic(frame, view.cfa, method=method, gains=gains, out=out)
    rebuild_partly_clipped(rgb, frame, view.cfa, normalised_gains(gains), estimated)
    return rgb


def _check_scalable(pages: np.ndarray, indices) -> None:
    """Values too small for float32 to scale to a picture (denormals: 1 / value overflows, and
    demosaicing and exposure divide by it) are refused as such, not left to become NaN."""
    tiny = float(np.finfo(np.float32).tiny)
    top = max(_largest_magnitude(pages[k]) for k in indices)
    if 0.0 < top < tiny:
        raise ValueError(f"its largest value is {top:.3g}, below float32's normal range "
                         f"({tiny:.3g}): too small to scale into a picture")


def _largest_magnitude(page: np.ndarray) -> float:
    """The largest finite |value| of ``page`` (0 if none). fmax and fmin skip NaN and make no
    temporary (a 30 Mpx page in 10 ms, not 0.3 s); only a page holding +-Inf takes the long way."""
    ends = [float(np.fmax.reduce(page, axis=None)), float(np.fmin.reduce(page, axis=None))]
    if all(np.isfinite(ends)):
        return max(abs(e) for e in ends)
    return float(np.max(np.abs(page), where=np.isfinite(page), initial=0.0))


def scene_rgb(camera: np.ndarray, *, gains, camera_to_srgb: np.ndarray | None,
              in_place: bool = False) -> np.ndarray:
    """Scene-referred linear sRGB (camera units): white balance, then the camera matrix
    (``None``: camera RGB is taken as linear sRGB). One 3 x 3 product per pixel, band by band;
    ``in_place`` overwrites ``camera`` (float32) instead of allocating a second image."""
    combined = np.diag(normalised_gains(gains))
    if camera_to_srgb is not None:
        combined = np.asarray(camera_to_srgb, np.float64) @ combined
    return _per_band(camera, combined, in_place=in_place)


def _per_band(rgb: np.ndarray, matrix: np.ndarray, *, in_place: bool,
              encode_space: str | None = None) -> np.ndarray:
    out = rgb if in_place else np.empty(rgb.shape, np.float32)
    m = np.asarray(matrix, np.float32).T

    def one_band(start: int) -> None:
        band = np.asarray(rgb[start:start + BAND_ROWS], np.float32) @ m
        if encode_space is not None:
            band = encode(band, encode_space)
        out[start:start + BAND_ROWS] = band

    # numpy releases the GIL in these loops: bands on every core, each a few MB of temporaries
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        list(pool.map(one_band, range(0, rgb.shape[0], BAND_ROWS)))
    return out


def blown_highlights(scene: np.ndarray, *, whole_frame: bool) -> np.ndarray:
    """The masked (NaN) pixels (rows, cols) of ``scene`` (rows, cols, 3) that are clipped
    highlights, which a photograph shows white (as a camera shows a blown highlight).

    In a view that fills its frame (``whole_frame``) every masked pixel is one. In a panorama or
    a refocused image only the masked areas enclosed by image data are: a masked area that
    reaches the image's edge is outside what the views cover, and stays black.
    """
    masked = ~np.isfinite(scene).all(axis=-1)
    if whole_frame or not masked.any():
        return masked
    return ndimage.binary_fill_holes(~masked) & masked


def exposure_scale(scene: np.ndarray, *, exposure_ev: float = 0.0,
                   white_percentile: float = 99.0) -> float:
    """The factor that maps the ``white_percentile`` of the scene's finite values to 1 (like
    dcraw's auto-brightness), times 2 ** exposure_ev."""
    if not np.isfinite(exposure_ev):
        raise ValueError(f"exposure_ev must be finite, got {exposure_ev}")
    sample = scene[::4, ::4].ravel()  # a 1/16 sample: the percentile of 30 MP costs seconds
    sample = sample[np.isfinite(sample)]
    if sample.size == 0:
        raise ValueError("the image has no finite pixel (everything masked)")
    reference = float(np.percentile(sample, white_percentile))
    if reference <= 0:
        raise ValueError(f"the {white_percentile:g}th percentile of the image is {reference:g} "
                         "(not positive): nothing to expose")
    return float(2.0 ** exposure_ev / reference)


def output_encoded(scene: np.ndarray, space: str, scale: float, *,
                   in_place: bool = False) -> np.ndarray:
    """Scene RGB to the output ``space``, scaled so that ``scale * scene = 1`` is white, clipped
    to [0, 1] and encoded (see :func:`plenocli.io.photo.encode`)."""
    return _per_band(scene, srgb_to_space(space) * scale, in_place=in_place,
                     encode_space=space)
