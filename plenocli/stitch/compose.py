"""Compositing through one map per view: the panorama canvas, the overlaps (exposure gains and
the residual measured there only), and the views resampled once into the panorama and blended.

Memory: the panorama is trimmed to what the views cover first (from their maps along its
edges), then blended band by band of its rows: every view's part of a band is mapped, resampled
and added, weighted, the band normalised in place and handed over (to the output file, for the
stage). The peak is the views and a few bands; no panorama and no weight canvas in memory.
Outside the overlaps a view's weight is its alone, so the normalisation leaves it as
resampled.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from plenocli.progress import step
from plenocli.stitch.errors import StitchError
from plenocli.stitch.kernels import accumulate, accumulate_channels, normalise, normalise_channels
from plenocli.stitch.nodata import ESTIMATE_WEIGHT, estimate_factors, measured_in
from plenocli.stitch.views import translation_matrix
from plenocli.stitch.warp import COVER_EPS_PX, ViewMap, feather, resample

Box = tuple[slice, slice]
BLEND_WORKERS = 2  # bands resampled while the next band's maps are computed


def place(frame_to_ref: list[np.ndarray], view_shape: tuple[int, int], *, k1: float = 0.0,
          rig=None) -> tuple[list[ViewMap], list[Box], np.ndarray, tuple[int, int]]:
    """Every view's map onto the panorama canvas, the canvas box its footprint covers, the
    reference -> panorama translation and the panorama (rows, cols). ``frame_to_ref[k]`` takes
    view k's frame (see :mod:`plenocli.stitch.warp`) to the reference (view 0's frame)."""
    maps = [ViewMap(view_shape, np.linalg.inv(f), k1, rig, k) for k, f in enumerate(frame_to_ref)]
    outlines = [m.outline() for m in maps]
    pts = np.concatenate(outlines)
    x0, y0 = np.ceil(pts.min(axis=0) - COVER_EPS_PX)
    x1, y1 = np.floor(pts.max(axis=0) + COVER_EPS_PX)
    shape = (int(y1 - y0) + 1, int(x1 - x0) + 1)
    if shape[0] * shape[1] > 16 * view_shape[0] * view_shape[1] * len(maps):
        raise StitchError(f"the transforms spread the views over {shape[1]} x {shape[0]} px; the "
                         "registration failed (views without a true overlap?)")
    offset = translation_matrix(-y0, -x0)
    back = np.linalg.inv(offset)
    maps = [ViewMap(view_shape, m.to_frame @ back, k1, rig, m.index) for m in maps]
    boxes = []
    for line in outlines:
        lo = np.ceil(line.min(axis=0) - [x0, y0] - COVER_EPS_PX).astype(int) - 1
        hi = np.floor(line.max(axis=0) - [x0, y0] + COVER_EPS_PX).astype(int) + 2
        boxes.append((slice(max(0, lo[1]), min(shape[0], hi[1])),
                      slice(max(0, lo[0]), min(shape[1], hi[0]))))
    return maps, boxes, offset, shape


def intersect(a: Box, b: Box) -> Box | None:
    rows = slice(max(a[0].start, b[0].start), min(a[0].stop, b[0].stop))
    cols = slice(max(a[1].start, b[1].start), min(a[1].stop, b[1].stop))
    return (rows, cols) if rows.stop > rows.start and cols.stop > cols.start else None


def region_shape(region: Box) -> tuple[int, int]:
    return region[0].stop - region[0].start, region[1].stop - region[1].start


def warp_region(view: np.ndarray, vmap: ViewMap, region: Box, holes=None, *,
                interpolation: int = cv2.INTER_LANCZOS4) -> tuple[np.ndarray, np.ndarray]:
    """A view's channels (C, rows, cols; NaN filled) resampled onto a panorama ``region``
    through its map (Lanczos-4, or ``interpolation``): (C, h, w) float32 and its feather
    weight (h, w), 0 where not covered."""
    out = np.empty((len(view),) + region_shape(region), np.float32)
    weight = np.empty(region_shape(region), np.float32)
    for band, mx, my, lost in vmap.bands(region):
        weight[band] = feather(mx, my, vmap.view_shape, lost, holes)
        out[:, band] = resample(view, mx, my, interpolation)
    return out, weight


def covered_box(maps: list[ViewMap], boxes: list[Box], holes: list) -> Box | None:
    """The bounding box of the canvas pixels some view covers (its feather weight > 0), or None.

    Each view's extent is found from the edges of its box inward, a strip of rows or columns at
    a time: the maps of a few strips, not of the footprint. The panorama is trimmed to it before
    it is blended, so its pixels can be written straight into the output."""
    extents = [e for e in (_view_extent(m, b, h) for m, b, h in zip(maps, boxes, holes,
                                                                        strict=True)) if e]
    if not extents:
        return None
    return (slice(min(e[0].start for e in extents), max(e[0].stop for e in extents)),
            slice(min(e[1].start for e in extents), max(e[1].stop for e in extents)))


EXTENT_STRIP = 8  # rows or columns mapped at a time while looking for a view's extent


def _view_extent(vmap: ViewMap, box: Box, hole) -> Box | None:
    ends = []
    for axis in (0, 1):
        first = _first_covered(vmap, box, hole, axis, inward=1)
        if first is None:
            return None
        ends.append(slice(first, _first_covered(vmap, box, hole, axis, inward=-1) + 1))
    return ends[0], ends[1]


def _first_covered(vmap: ViewMap, box: Box, hole, axis: int, inward: int) -> int | None:
    """The first row (axis 0) or column of ``box`` holding a covered pixel, from its start
    (``inward`` 1) or its end (-1)."""
    lo, hi = box[axis].start, box[axis].stop
    for k in range(0, hi - lo, EXTENT_STRIP):
        strip = (slice(lo + k, min(hi, lo + k + EXTENT_STRIP)) if inward > 0
                 else slice(max(lo, hi - k - EXTENT_STRIP), hi - k))
        region = list(box)
        region[axis] = strip
        found = np.flatnonzero(coverage(vmap, tuple(region), hole).any(axis=1 - axis))
        if found.size:
            return strip.start + int(found[0] if inward > 0 else found[-1])
    return None


def coverage(vmap: ViewMap, region: Box, hole) -> np.ndarray:
    """Where the view covers ``region`` (its feather weight > 0), from its maps alone."""
    out = np.empty(region_shape(region), bool)
    for band, mx, my, lost in vmap.bands(region):
        out[band] = feather(mx, my, vmap.view_shape, lost, hole) > 0
    return out


def crop(maps: list[ViewMap], boxes: list[Box], box: Box) -> tuple[list[ViewMap], list]:
    """The maps and boxes on the canvas cropped to ``box`` (a view's box None where it lies
    outside)."""
    to_full = translation_matrix(box[0].start, box[1].start)
    cropped = []
    for b in boxes:
        inside = intersect(b, box)
        cropped.append(None if inside is None else tuple(
            slice(s.start - o.start, s.stop - o.start) for s, o in zip(inside, box, strict=True)))
    return [ViewMap(m.view_shape, m.to_frame @ to_full, m.k1, m.rig, m.index)
            for m in maps], cropped


# the panorama is blended in bands of at least this many pixels (OpenCV's remap slows on thin
# bands: 35 rows took 1.36 x one call, 256 rows 1.07 x)
BLEND_BAND_PIXELS = 1 << 22


def blend(views: Sequence[np.ndarray], maps: list[ViewMap], boxes: list, holes: list,
          gains: np.ndarray, shape: tuple[int, int, int], write_rows,
          estimated: Sequence | None = None) -> np.ndarray:
    """Blend the feathered panorama of ``shape`` (C, rows, cols) float32 (NaN where no view
    covers), handing each band of rows to ``write_rows(rows, pixels)`` once it is final (in
    order); returns the pixels some view covers (rows, cols).

    Band by band of panorama rows, each view's part of the band is resampled once through its
    map and added, weighted by its distance to its edge; the band is then normalised in place
    and written. So no whole canvas and no weight canvas is held: the output file is written
    band by band. The maps of a band are computed here while worker threads resample the parts
    before it (numpy, OpenCV and the compiled kernels release the GIL); the parts are added in
    view order by one compiled pass, so the sums are those of a serial loop. A band is written
    by a thread of its own while the next ones are summed (the write is memory-bound kernel
    work: 1.4 GB into the page cache costs seconds at the 5D Mark IV's size).

    ``estimated``: per view, the channels its source estimated (a Bayer view's rebuilt clipped
    channel, :class:`plenocli.colour.highlights.Estimated`) or None. An estimate is a colour
    guessed from the pixels around, not the view's light: where another view measured that
    channel it weighs ESTIMATE_WEIGHT of the view's feather weight there, so the measured value
    is the panorama's; where no view measured it the estimate is all there is and is kept.
    A band a view's estimate reaches is summed with a total per channel (C x the one total);
    every other band as before, one weight for all channels."""
    n_chan, rows, cols = shape
    estimated = list(estimated) if estimated is not None else [None] * len(views)
    step_rows = max(1, min(rows, BLEND_BAND_PIXELS // cols))
    n_bands = -(-rows // step_rows)
    covered = np.empty((rows, cols), bool)
    # band j is summed in buffers j % 2 while band j - 1 may still be open
    buffers = [_BandSums(n_chan, step_rows, cols) for _ in range(2)]
    pending: deque = deque()  # (band number, rows within the band, cols, gain, job)
    open_bands: deque = deque()  # (band number, its rows)
    writes: list = [None, None]  # the write of the band last summed in each buffer

    def add_oldest() -> None:
        j, band_rows, band_cols, gain, job = pending.popleft()
        buffers[j % 2].add(band_rows, band_cols, *job.result(), gain)

    def close_bands(before: int) -> None:
        while open_bands and open_bands[0][0] < before:
            j, band = open_bands.popleft()
            while pending and pending[0][0] <= j:
                add_oldest()
            pixels = buffers[j % 2].normalise(covered[band])
            writes[j % 2] = writer.submit(write_rows, band, pixels)

    with ThreadPoolExecutor(max_workers=BLEND_WORKERS) as pool, \
            ThreadPoolExecutor(max_workers=1) as writer:
        for j in range(n_bands):
            close_bands(j - 1)  # band j reuses the buffers of band j - 2, once written
            if writes[j % 2] is not None:
                writes[j % 2].result()
            band = slice(j * step_rows, min(rows, (j + 1) * step_rows))
            buffers[j % 2].start(band.stop - band.start)
            open_bands.append((j, band))
            for k, (view, vmap, box) in enumerate(zip(views, maps, boxes, strict=True)):
                part = None if box is None else intersect(box, (band, slice(0, cols)))
                if part is None:
                    continue
                step(f"blending band {j + 1} of {n_bands}, view {k + 1} of {len(views)}")
                gain = gains[k].astype(np.float32)
                for piece_rows, piece_cols, job in _resample_part(pool, band, part, view, vmap,
                                                                  holes[k], estimated[k]):
                    pending.append((j, piece_rows, piece_cols, gain, job))
                    while len(pending) > BLEND_WORKERS:
                        add_oldest()
        close_bands(n_bands)
        for done in writes:
            if done is not None:
                done.result()
    return covered


class _BandSums:
    """A band's weighted sums (C, rows, cols) and their total weight (rows, cols); once a piece
    with a share per channel comes (:func:`_band`), a total per channel (C, rows, cols),
    allocated then: a band no estimate reaches is summed as ever, one weight for all."""

    def __init__(self, n_chan: int, rows: int, cols: int):
        self.sums = np.empty((n_chan, rows, cols), np.float32)
        self.total = np.empty((rows, cols), np.float32)
        self.totals: np.ndarray | None = None
        self.split = False
        self.height = rows

    def start(self, height: int) -> None:
        self.total[:] = 0  # the sums are set where a first weight is added
        self.split = False
        self.height = height

    def add(self, rows: slice, cols: slice, img: np.ndarray, weight: np.ndarray,
            factor: np.ndarray | None, gain: np.ndarray) -> None:
        scaled = bool((gain != 1).any())
        if factor is None and not self.split:
            accumulate(self.sums[:, rows, cols], self.total[rows, cols], img, weight, gain,
                       scaled)
            return
        if not self.split:  # the band's first estimate: what is summed so far, per channel
            if self.totals is None:
                self.totals = np.empty(self.sums.shape, np.float32)
            self.totals[:] = self.total
            self.split = True
        accumulate_channels(self.sums[:, rows, cols], self.totals[:, rows, cols], img, weight,
                            _NO_FACTOR if factor is None else factor, gain, scaled,
                            factor is None)

    def normalise(self, covered: np.ndarray) -> np.ndarray:
        """The band's pixels, normalised in place; marks ``covered``."""
        h = self.height
        if self.split:
            normalise_channels(self.sums[:, :h], self.totals[:, :h], covered)
        else:
            normalise(self.sums[:, :h], self.total[:h], covered)
        return self.sums[:, :h]


def _resample_part(pool, band: slice, part: Box, view: np.ndarray, vmap: ViewMap, hole,
                   estimated=None):
    """Queue the resampling of a view's ``part`` of a panorama ``band``, a piece of rows at a
    time: yields (rows within the band, columns, the job giving the piece, its weight and its
    channels' shares of it, see :func:`_band`)."""
    for piece, mx, my, lost in vmap.bands(part):
        span = on_view(mx, my, lost, vmap.view_shape)
        if span is None:
            continue
        mx, my = mx[:, span], my[:, span]
        lost = lost[:, span] if lost is not None else None
        first = part[0].start - band.start + piece.start
        yield (slice(first, first + piece.stop - piece.start),
               slice(part[1].start + span.start, part[1].start + span.stop),
               pool.submit(_band, view, mx, my, lost, vmap.view_shape, hole, estimated))


def on_view(mx: np.ndarray, my: np.ndarray, lost: np.ndarray | None,
            view_shape: tuple[int, int]) -> slice | None:
    """The columns of a band whose maps reach the view (a source within a pixel of it, a ray
    that gets through): only they can be covered; None when none does. A prism bends a view's
    footprint, so its bands are narrower than its box (the demo rig's view A: 0.82 x)."""
    rows, cols = view_shape
    on = (mx >= -1) & (mx <= cols) & (my >= -1) & (my <= rows)
    if lost is not None:
        on &= ~lost
    found = np.flatnonzero(on.any(axis=0))
    return slice(int(found[0]), int(found[-1]) + 1) if found.size else None


def _band(view: np.ndarray, mx: np.ndarray, my: np.ndarray, lost, view_shape, hole,
          estimated=None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A band of a view resampled at its maps, its feather weight and the share of it each
    channel takes (:func:`plenocli.stitch.nodata.estimate_factors`; None: all of it)."""
    return (resample(view, mx, my), feather(mx, my, view_shape, lost, hole),
            estimate_factors(estimated, mx, my, view_shape, len(view)))


_NO_FACTOR = np.empty((0, 0, 0), np.float32)  # accumulate_channels' factor when it reads none


def multiband_blend(views: Sequence[np.ndarray], maps: list[ViewMap], boxes: list[Box],
                    holes: list, gains: np.ndarray, shape: tuple[int, int],
                    estimated: Sequence | None = None) -> np.ndarray:
    """Burt-Adelson multi-band blend, channel by channel over the whole canvas (V canvases per
    channel); each view still resampled once per channel through its map. A channel a view's
    source estimated weighs ESTIMATE_WEIGHT of its weight there (see :func:`blend`), so the
    seam masks give it to a view that measured it, where one covers it; and its pixels there
    are the weighted mean's (the measured value), which its coarse levels reach past the
    masks."""
    n_chan, n_views = views[0].shape[0], len(views)
    estimated = list(estimated) if estimated is not None else [None] * n_views
    known = [measured_in(e, m, b, n_chan) for e, m, b in zip(estimated, maps, boxes,
                                                             strict=True)]
    panorama = np.full((n_chan,) + shape, np.nan, np.float32)
    for c in range(n_chan):
        images = np.zeros((n_views,) + shape, np.float32)
        weights = np.zeros((n_views,) + shape, np.float32)
        for k in range(n_views):
            step(f"multi-band: channel {c + 1} of {n_chan}, view {k + 1} of {n_views}")
            img, weight = warp_region(views[k][c:c + 1], maps[k], boxes[k], holes[k])
            if known[k][c] is not None:
                weight[~known[k][c]] *= np.float32(ESTIMATE_WEIGHT)
            weights[k][boxes[k]] = weight
            images[k][boxes[k]] = np.where(weight > 0, img[0] * np.float32(gains[k, c]), 0)
        total = weights.sum(axis=0)
        covered = total > 0
        fallback = (images * weights).sum(axis=0) / np.maximum(total, 1e-12)
        for k in range(n_views):  # the pyramid's coarse levels reach past the seam masks too
            if known[k][c] is not None:
                guessed = images[k][boxes[k]]
                guessed[~known[k][c]] = fallback[boxes[k]][~known[k][c]]
        panorama[c] = np.where(covered, _multiband(images, weights, fallback), np.nan)
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
