"""No-data (NaN) pixels: isolated ones estimated from their neighbours for the measurements,
holes kept out of them; in the panorama every one stays no data.

NaN marks a clipped or unknown pixel (bias writes it where a photosite clipped): a hot pixel,
a few clipped photosites of a highlight, a dead row or column. The measurements need a
neighbourhood around each pixel they use (the high-pass's support, the search mask's 2-px
erosion, the 8 x 8 reach of the resampling kernel, the feather's distance to no data), so a
measurement that treats every NaN as a hole loses far more than the pixel: 1 % of a view's
pixels NaN, scattered, left no block of the seam measurable and the views were refused
(audit 18 F2), however they were placed (registered, --overlap, --model homography, a saved
transform). So before anything is measured, a NaN pixel with at least FILL_KNOWN of the
FILL_WINDOW x FILL_WINDOW pixels around it known is given their Gaussian-weighted mean; it
then costs the registration, the seam check and the exposure gains only itself. A larger hole
(a clipped area, the unknown part of a view; its inside has fewer known neighbours) stays NaN
there: measured around and feathered as before.

The panorama does not take these estimates: each NaN pixel keeps weight 0 (its resampling
footprint too), so it is the other view's where one overlaps it and NaN where none does; the
exposure gains are sums over known pixels only. Only the feather's distance to no data leaves
the isolated pixels out: a sprinkle of them would otherwise bring every weight down to a pixel
or two and make the seam a mottle of both views.

Why it generalises: it uses only what every view with NaN pixels has, how many of each
pixel's neighbours are known; a pixel with half of them known is interpolated within a pixel
or two of known data, whatever the scene, the camera or the pixel's cause.
"""

from __future__ import annotations

import contextlib

import cv2
import numpy as np

from plenocli.stitch.errors import StitchError
from plenocli.stitch.views import erode

FILL_WINDOW = 5  # the pixels around a NaN pixel it is estimated from (within 2 px)
FILL_KNOWN = 0.5  # of them known, at least: else it belongs to a hole
FILL_SIGMA_PX = 1.0  # the estimate's Gaussian weights: the nearest known pixels count most
# a view whose pixels are left out of the measurements (NaN not filled, with the 2-px margin the
# search mask keeps from them) beyond this fraction holds too little to be placed: a refusal is
# then said to be the NaN's, not the layout's, the overlap's or the rig's
MAX_LOST = 0.5
# a panorama pixel is measured in a channel when its bilinear footprint holds no estimated pixel
# of that channel (the feather's rule for NaN pixels, :func:`plenocli.stitch.warp.feather`)
MEASURED_SHARE = 0.999
# an estimated channel's blend weight, as a share of the view's feather weight: where another
# view measured that channel it decides (a feather weight is at least ~1 px, the estimate's at
# most the view's half-size times this: 5e-3 of it at 10000 px); where none did, the estimate is
# all there is and is kept
ESTIMATE_WEIGHT = 1e-6


class NoData:
    """The views' no-data pixels: per view its validity (all channels known; None: every pixel
    is) and the NaN pixels estimated for the measurements (None: none); and the channels its
    source estimated (``estimated``: a Bayer view's rebuilt clipped channels, see
    :meth:`plenocli.colour.highlights.Estimated.region`; None per view, or for all: none)."""

    def __init__(self, stack: np.ndarray, estimated=None):
        self.estimated = list(estimated) if estimated is not None else [None] * len(stack)
        self.copied = False
        self.valid: list[np.ndarray | None] = []
        self.isolated: list[np.ndarray | None] = []
        for view in stack:
            valid = _valid(view)
            self.valid.append(valid)
            self.isolated.append(None if valid is None else _isolated(valid))

    def measured(self, stack: np.ndarray) -> np.ndarray:
        """The views (V, C, rows, cols) with their isolated NaN pixels estimated from their
        neighbours: a copy when some are (``copied``; the blend later fills its holes in
        place), else ``stack`` itself."""
        self.copied = any(iso is not None and iso.any() for iso in self.isolated)
        if not self.copied:
            return stack
        out = stack.copy()
        for view, valid, iso in zip(out, self.valid, self.isolated, strict=True):
            if iso is not None and iso.any():
                _fill(view, valid, iso)
        return out

    def lost(self) -> list[float]:
        """Per view, the fraction of its pixels the measurements leave out: NaN not estimated,
        and the 2-px margin kept from them."""
        out = []
        for valid, iso in zip(self.valid, self.isolated, strict=True):
            if valid is None:
                out.append(0.0)
                continue
            known = valid | iso
            out.append(0.0 if known.all() else 1.0 - float(erode(known, 2).mean()))
        return out

    def unknown(self, k: int) -> float:
        valid = self.valid[k]
        return 0.0 if valid is None else 1.0 - float(valid.mean())

    def holes(self) -> list:
        """Per view, what the feather needs (:func:`plenocli.stitch.warp.feather`): None for a
        view with no NaN, else (valid as float32, distance (px) to its nearest pixel of a hole,
        or None when every NaN pixel is isolated)."""
        out = []
        for valid, iso in zip(self.valid, self.isolated, strict=True):
            if valid is None:
                out.append(None)
                continue
            known = valid | iso
            distance = None if known.all() else cv2.distanceTransform(
                known.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            out.append((valid.astype(np.float32), distance))
        return out

    @contextlib.contextmanager
    def too_few_known(self):
        """A refusal (StitchError) where a view's measurements lose more than MAX_LOST of it to
        NaN says so: no layout, overlap, rig or model helps there."""
        try:
            yield
        except StitchError as err:
            lost = self.lost()
            k = int(np.argmax(lost))
            if lost[k] <= MAX_LOST or self.unknown(k) >= 1:  # (a view of no data says so)
                raise
            raise StitchError(
                f"view {k} has {100 * self.unknown(k):.0f} % of its pixels unknown (NaN: "
                "clipped or unknown), too densely to estimate them from the known pixels "
                f"around them: {100 * lost[k]:.0f} % of the view is left out of the "
                "measurements, too little to register it and check its overlaps; stitch "
                "views with more known pixels") from err


def _valid(view: np.ndarray) -> np.ndarray | None:
    """Where every channel of a view (C, rows, cols) is known; None when all are."""
    # the usual view: one pass and no mask (a sum that overflows takes the masked way)
    if np.isfinite(np.sum(view, dtype=np.float32)):
        return None
    valid = np.isfinite(view[0])
    for channel in view[1:]:  # channel by channel: fast whatever their layout in memory
        valid &= np.isfinite(channel)
    return None if valid.all() else valid


def _isolated(valid: np.ndarray) -> np.ndarray:
    """The NaN pixels with at least FILL_KNOWN of the pixels of the view around them (within
    the window) known."""
    size = (FILL_WINDOW, FILL_WINDOW)
    known = cv2.boxFilter(valid.astype(np.float32), -1, size, normalize=False,
                          borderType=cv2.BORDER_CONSTANT)
    inside = cv2.boxFilter(np.ones(valid.shape, np.float32), -1, size, normalize=False,
                           borderType=cv2.BORDER_CONSTANT)
    return ~valid & (known >= FILL_KNOWN * inside)


def _fill(view: np.ndarray, valid: np.ndarray, isolated: np.ndarray) -> None:
    """Estimate a view's (C, rows, cols) ``isolated`` pixels in place: the Gaussian-weighted
    mean of the known pixels within the window."""
    size = (FILL_WINDOW, FILL_WINDOW)
    weight = cv2.GaussianBlur(valid.astype(np.float32), size, FILL_SIGMA_PX,
                              borderType=cv2.BORDER_CONSTANT)[isolated]
    for channel in view:
        known = np.where(valid, channel, np.float32(0))
        channel[isolated] = cv2.GaussianBlur(known, size, FILL_SIGMA_PX,
                                             borderType=cv2.BORDER_CONSTANT)[isolated] / weight


def measured_in(estimated, vmap, block: tuple[slice, slice], n_chan: int) -> list:
    """Per channel, where a view measured it on the panorama ``block`` (bool; None: every
    pixel): see :func:`measured_at`, band by band of the view's maps."""
    out: list = [None] * n_chan
    if estimated is None:
        return out
    shape = (block[0].stop - block[0].start, block[1].stop - block[1].start)
    for band, mx, my, _ in vmap.bands(block):
        for c, known in enumerate(measured_at(estimated, mx, my, vmap.view_shape, n_chan)):
            if known is not None:
                if out[c] is None:
                    out[c] = np.ones(shape, bool)
                out[c][band] = known
    return out


def measured_at(estimated, mx: np.ndarray, my: np.ndarray, view_shape: tuple[int, int],
                n_chan: int) -> list:
    """Per channel, where a view measured it at its maps (bool; None: everywhere): not where
    its resampling reaches a pixel whose channel its source estimated (``estimated.region(c,
    rows, cols)``: bool, or None for a channel never estimated), as the feather leaves out a
    NaN pixel's footprint."""
    out: list = [None] * n_chan
    if estimated is None:
        return out
    rows, cols = view_shape
    on = (mx >= -1) & (mx <= cols) & (my >= -1) & (my <= rows)
    if not on.any():
        return out
    top, left = (max(int(np.floor(v[on].min())) - 1, 0) for v in (my, mx))
    bottom, right = int(np.ceil(my[on].max())) + 2, int(np.ceil(mx[on].max())) + 2
    window = (slice(top, min(bottom, rows)), slice(left, min(right, cols)))
    for c in range(n_chan):
        guessed = estimated.region(c, *window)
        if guessed is None or not guessed.any():
            continue
        out[c] = cv2.remap((~guessed).astype(np.float32), mx - np.float32(left),
                           my - np.float32(top), cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE) > MEASURED_SHARE
    return out


def estimate_factors(estimated, mx: np.ndarray, my: np.ndarray, view_shape: tuple[int, int],
                     n_chan: int) -> np.ndarray | None:
    """The blend's per-channel share of a view's feather weight at its maps, (C, h, w)
    float32: 1 where it measured the channel, ESTIMATE_WEIGHT where its source estimated it;
    None where it measured every channel (the common case: one weight for all channels)."""
    known = measured_at(estimated, mx, my, view_shape, n_chan)
    if all(k is None for k in known):
        return None
    out = np.ones((n_chan,) + np.shape(mx), np.float32)
    for factor, k in zip(out, known, strict=True):
        if k is not None:
            factor[~k] = ESTIMATE_WEIGHT
    return out
