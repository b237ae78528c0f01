"""Undistortion of views seen through prisms at the main lens's stop (a prism rig).

A prism rig (paper sections 3, 5.2, 6) puts a thin prism over part of the pupil of a thin main
lens of focal ``F``; each view (sub-aperture image) sees the scene through its own pupil part and
prism. The prism deviates the view's field by about (n - 1) A, but not uniformly: at non-normal
incidence the deviation grows towards the field's edges, so the lines of the scene bend and two
views disagree over their overlap by many pixels. This module maps every view into one common,
undistorted frame: the image the main lens alone would form of the scene plane (at
``object_distance_mm``, or of directions at infinity), on the views' pixel grid, extended past the
sensor. Views mapped there differ by no more than the rig model's error, so they stitch by a
small translation.

Coordinates: a view pixel (x = column, y = row) has its centre at sensor position
``((x + 0.5) - cols / 2, (y + 0.5) - rows / 2) * pixel_mm`` (mm from the optical axis; x right,
y down, looking from the sensor through the lens). The common frame uses the same pixel grid:
common pixel = (sensor-plane position of the undeviated image) / pixel_mm + (cols / 2 - 0.5,
rows / 2 - 0.5), so for a view without prism (and an object at infinity) the map is the identity
and the optical axis sits at common pixel ((cols - 1) / 2, (rows - 1) / 2).

Ray model: :mod:`plenocli.optics.prism` (exact for a thin lens and thin prisms at the stop), the
one the simulator :mod:`plenocli.synth.prismcam` renders with. The view pixel at sensor point s
sends its ray through the pupil part's centroid p towards the conjugate point q = -s z / D; the
prism deviates it; it meets the scene plane z at C. The common coordinate is -C D / z. The
inverse traces the ray back through the prism (exact, no iteration).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict

import cv2
import numpy as np
from scipy import ndimage

from plenocli.model.rig import PrismRig, ViewOptics
from plenocli.optics import prism as optics_prism
from plenocli.stitch.kernels import band_maps
from plenocli.stitch.views import fill_nan_channels

MAP_BAND_PIXELS = 1 << 20  # canvas pixels mapped at a time (OpenCV's remap slows on thin bands)
TRACE_BAND_PIXELS = 1 << 18  # rays traced at a time (float64 temporaries of a few tens of MB)
MAP_NODES_PER_VIEW = 256  # rays traced exactly across a view's width for the remap maps
MAP_TOLERANCE_PX = 1e-6  # interpolated maps further than this from a traced ray: traced
NODE_CACHE_BYTES = 128 << 20  # node grids kept for the next capture of a batch (_node_grid)
_NODE_CACHE: OrderedDict = OrderedDict()
_NODE_LOCK = threading.Lock()


def _check_view(rig: PrismRig, view: int) -> ViewOptics:
    if not 0 <= view < len(rig.views):
        raise ValueError(f"view {view} is not in the rig ({len(rig.views)} views)")
    return rig.views[view]


def view_to_common(rig: PrismRig, view: int, x: np.ndarray, y: np.ndarray,
                   shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Common-frame pixel coordinates (x, y) of view pixels ``x``, ``y`` (any equal shapes) of a
    view of ``shape`` = (rows, cols). NaN where the prism reflects the ray totally."""
    return _through_prism(rig, view, x, y, shape, reverse=False)


def common_to_view(rig: PrismRig, view: int, cx: np.ndarray, cy: np.ndarray,
                   shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`view_to_common`: view pixel (x, y) seeing common pixel (cx, cy)."""
    return _through_prism(rig, view, cx, cy, shape, reverse=True)


def _through_prism(rig: PrismRig, view: int, x, y, shape: tuple[int, int], *,
                   reverse: bool) -> tuple[np.ndarray, np.ndarray]:
    """Trace pixels (x, y) out through the lens to the scene (or infinity), deviate the ray by
    the view's prism (forwards, or backwards when ``reverse``) and trace it back to a pixel.
    The same geometry both ways, so the inverse is exact and needs no iteration."""
    v = _check_view(rig, view)
    rows, cols = shape
    pix = rig.sensor_mm / cols
    s = np.stack([((np.asarray(x, np.float64) + 0.5) - cols / 2) * pix,
                  ((np.asarray(y, np.float64) + 0.5) - rows / 2) * pix], axis=-1).reshape(-1, 2)
    z = rig.object_distance_mm
    dist = optics_prism.image_distance_mm(rig.focal_mm, z)
    hits = optics_prism.scene_hits(
        s, optics_prism.pupil_centroid_mm(rig.aperture_mm, v.pupil), image_distance_mm=dist,
        object_distance_mm=z, prism=(rig.prism_n, rig.prism_apex_deg), towards=v.prism,
        reverse=reverse)
    u = -dist * hits if math.isinf(z) else -hits * (dist / z)  # the undeviated image point
    out_x = u[:, 0] / pix + cols / 2 - 0.5
    out_y = u[:, 1] / pix + rows / 2 - 0.5
    return out_x.reshape(np.shape(x)), out_y.reshape(np.shape(x))


def common_extent(rig: PrismRig, view: int, shape: tuple[int, int]) -> np.ndarray:
    """Bounding box [x0, y0, x1, y1] (common pixels) of the view's outline in the common frame."""
    rows, cols = shape
    t = np.linspace(0.0, 1.0, 257)
    xs = np.concatenate([t * (cols - 1), np.full_like(t, cols - 1), t * (cols - 1),
                         np.zeros_like(t)])
    ys = np.concatenate([np.zeros_like(t), t * (rows - 1), np.full_like(t, rows - 1),
                         t * (rows - 1)])
    cx, cy = view_to_common(rig, view, xs, ys, shape)
    ok = np.isfinite(cx) & np.isfinite(cy)
    if not ok.any():
        raise ValueError(f"view {view}: the prism reflects every ray totally; check the rig")
    return np.array([cx[ok].min(), cy[ok].min(), cx[ok].max(), cy[ok].max()])


def canvases(rig: PrismRig, shape: tuple[int, int]) -> tuple[np.ndarray, tuple[int, int]]:
    """The views' canvases in the common undistorted frame: one equal-size canvas per view
    holding its whole footprint.

    Returns
    -------
    origins : (V, 2) [row, col] common-frame pixel of each canvas's pixel (0, 0): canvas pixel
        (r, c) of view k is common pixel (r + origins[k, 0], c + origins[k, 1]). The views'
        relative positions predicted by the rig are the differences of the origins.
    size : the canvases' (rows, cols).
    """
    rows, cols = shape
    boxes = np.array([common_extent(rig, k, shape) for k in range(len(rig.views))])
    origin_xy = np.floor(boxes[:, :2])
    size = np.ceil(boxes[:, 2:] - origin_xy).max(axis=0).astype(int) + 1
    if size.prod() > 16 * rows * cols:
        raise ValueError(f"the rig spreads a view over {size[0]} x {size[1]} px; check its "
                         "focal_mm, sensor_mm and prism")
    return origin_xy[:, ::-1].copy(), (int(size[1]), int(size[0]))


def map_pitch(shape: tuple[int, int]) -> int:
    """The node pitch (px) of the remap maps of a view of ``shape``."""
    return int(np.clip(shape[1] // MAP_NODES_PER_VIEW, 1, 16))


def undistort_region(image: np.ndarray, rig: PrismRig, view: int, origin_xy: np.ndarray,
                     region: tuple[int, int]) -> np.ndarray:
    """A (rows, cols) view in the common undistorted frame over a region of ``region`` =
    (rows', cols') pixels whose pixel (0, 0) is common pixel ``origin_xy`` (x, y): float32,
    Lanczos-4, NaN where the view does not cover it. Only the part of the view the region's
    maps reach (and the kernel's 4 px around it) is NaN-filled and read."""
    rows, cols = image.shape
    bands = []
    lo, hi = np.array([cols, rows]), np.array([-1, -1])
    for band, mx, my, bad in _view_maps(rig, view, origin_xy, region, (rows, cols)):
        # region pixels more than a pixel off the view come out NaN whatever is resampled
        # there (they are pointed inside below: Lanczos-4's border path is slow)
        off_view = (mx < -1) | (mx > cols) | (my < -1) | (my > rows)
        if not off_view.all():
            on_x, on_y = mx[~off_view], my[~off_view]
            lo = np.minimum(lo, [np.floor(on_x.min()), np.floor(on_y.min())])
            hi = np.maximum(hi, [np.floor(on_x.max()), np.floor(on_y.max())])
        bands.append((band, mx, my, bad, off_view))
    x0, y0 = np.maximum(lo.astype(int) - 4, 0)
    x1, y1 = np.minimum(hi.astype(int) + 5, [cols, rows])
    if x1 - x0 < 9 or y1 - y0 < 9:
        x0, y0, x1, y1 = 0, 0, cols, rows
    crop = np.asarray(image[y0:y1, x0:x1], np.float32)
    valid = np.isfinite(crop).astype(np.float32)
    filled = fill_nan_channels(crop[np.newaxis])[0]
    out = np.empty(region, np.float32)
    for band, mx, my, bad, off_view in bands:
        # every pixel on the view reads within the crop (exact: integer shifts of the maps)
        mx -= np.float32(x0)
        my -= np.float32(y0)
        cover = cv2.remap(valid, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                          borderValue=0) > 0.999
        cover &= ~bad
        mx[off_view] = 4
        my[off_view] = 4
        warped = cv2.remap(filled, mx, my, cv2.INTER_LANCZOS4, borderMode=cv2.BORDER_REPLICATE)
        out[band] = np.where(cover, warped, np.nan)
    return out


STRIP_MARGIN_PX = 64  # past the searched overlap: the high-pass (4 sigma) and refinement margins


def rig_strips(luma: np.ndarray, rig: PrismRig, origins: np.ndarray, size: tuple[int, int],
               a: int, b: int, direction: str, expected, across: tuple[int, int] | None = None
               ) -> tuple:
    """The overlap strips of views a and b's canvases (see :func:`canvases`) in the common
    frame, from their luminance (V, rows, cols): the part of each canvas that the rig's predicted
    shift, within its tolerance and a margin, can bring over the other. ``across`` = (lo, hi)
    limits a's strip across the stitching direction to those canvas rows (columns for "v") and
    b's to the ones the prediction brings there; default: the whole canvases. Returns (strip of
    a, strip of b, [dy, dx] of a's strip in its canvas, the same for b). Strips start on the
    maps' node grid and on multiples of 4, so they hold exactly the pixels of the whole
    canvases."""
    (prior, tol) = expected
    axis = 1 if direction == "h" else 0
    along = prior[axis]
    pitch = map_pitch(luma.shape[1:])
    align = pitch * 4 // math.gcd(pitch, 4)
    start = max(0, int(np.floor(along - tol)) - STRIP_MARGIN_PX) // align * align
    stop = min(size[axis], int(np.ceil(size[axis] - along + tol)) + STRIP_MARGIN_PX)
    lo, hi = across if across is not None else (0, size[1 - axis])
    shift_across = int(round(prior[1 - axis])) if across is not None else 0
    out, offsets = [], []
    for view, span, moved in ((a, (start, size[axis]), 0), (b, (0, stop), shift_across)):
        first = max(0, lo - moved) // align * align
        last = min(size[1 - axis], hi - moved)
        offset, shape = [0, 0], list(size)
        offset[axis], offset[1 - axis] = span[0], first
        shape[axis], shape[1 - axis] = span[1] - span[0], last - first
        origin_xy = origins[view, ::-1] + offset[::-1]
        out.append(undistort_region(luma[view], rig, view, origin_xy, tuple(shape)))
        offsets.append(tuple(offset))
    return out[0], out[1], offsets[0], offsets[1]


def _traced(rig: PrismRig, view: int, x: np.ndarray, y: np.ndarray,
            shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`common_to_view` in bands of about TRACE_BAND_PIXELS points (the ray tracing's
    float64 temporaries stay a few tens of MB); x, y are common pixels of equal 2-D shape."""
    vx, vy = np.empty(x.shape), np.empty(x.shape)
    step = max(1, TRACE_BAND_PIXELS // max(1, x.shape[1]))
    for r0 in range(0, x.shape[0], step):
        band = slice(r0, r0 + step)
        vx[band], vy[band] = common_to_view(rig, view, x[band], y[band], shape)
    return vx, vy


def _cubic_weights(n: int, pitch: int) -> tuple[np.ndarray, np.ndarray]:
    """For pixels 0..n-1 on a node grid of ``pitch`` px starting one pitch before pixel 0: the
    index of each pixel's first stencil node and its 4-point Lagrange weights (n, 4)."""
    pos = np.arange(n)
    first = pos // pitch  # nodes first .. first + 3 sit at -1, 0, 1, 2 pitches from it
    t = (pos % pitch / pitch)[:, None]
    weights = np.concatenate([-t * (t - 1) * (t - 2) / 6, (t + 1) * (t - 1) * (t - 2) / 2,
                              -(t + 1) * t * (t - 2) / 2, (t + 1) * t * (t - 1) / 6], axis=1)
    return first, weights


def _rough_cells(rig: PrismRig, view: int, nodes: list[np.ndarray], node_x: np.ndarray,
                 node_y: np.ndarray, pitch: int, shape: tuple[int, int]) -> np.ndarray:
    """(cells y, cells x) bool: the grid cells (and their neighbours) where the interpolated
    map misses the ray traced through the cell's centre by more than MAP_TOLERANCE_PX, or has
    no value (near total reflection, where the map steepens); their pixels are traced."""
    mid = np.array([-1.0, 9.0, 9.0, -1.0]) / 16  # 4-point Lagrange weights half-way
    centre_x = node_x[1:-2] + pitch / 2
    centre_y = node_y[1:-2] + pitch / 2
    traced = _traced(rig, view, *np.meshgrid(centre_x, centre_y), shape)
    rough = np.zeros(traced[0].shape, bool)
    for node, exact in zip(nodes, traced, strict=True):
        along = sum(node[:, j:j + len(centre_x)] * mid[j] for j in range(4))
        interpolated = sum(along[j:j + len(centre_y)] * mid[j] for j in range(4))
        rough |= ~(np.abs(interpolated - exact) <= MAP_TOLERANCE_PX)
    return ndimage.binary_dilation(rough, structure=np.ones((3, 3), bool))


def _node_grid(rig: PrismRig, view: int, origin_xy, canvas: tuple[int, int],
               shape: tuple[int, int]) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """The traced nodes of a canvas's maps interpolated along its rows (one array per
    coordinate), the cells traced per pixel, and each column's first stencil node (see
    :func:`_view_maps`). Kept for the canvases mapped last (NODE_CACHE_BYTES): the captures of a
    batch stitched by one transform map the same canvases of the same rig, and tracing is most
    of what their maps cost. Callers only read them."""
    key = (rig, view, float(origin_xy[0]), float(origin_xy[1]), tuple(canvas), tuple(shape))
    with _NODE_LOCK:
        if key in _NODE_CACHE:
            _NODE_CACHE.move_to_end(key)
            return _NODE_CACHE[key]
    rows, cols = canvas
    pitch = map_pitch(shape)
    node_y = (np.arange((rows - 1) // pitch + 4) - 1.0) * pitch + origin_xy[1]
    node_x = (np.arange((cols - 1) // pitch + 4) - 1.0) * pitch + origin_xy[0]
    nodes = _traced(rig, view, *np.meshgrid(node_x, node_y), shape)
    lost = ndimage.binary_dilation(~(np.isfinite(nodes[0]) & np.isfinite(nodes[1])),
                                   structure=np.ones((3, 3), bool))
    nodes = [np.where(lost, np.nan, node) for node in nodes]
    rough = _rough_cells(rig, view, nodes, node_x, node_y, pitch, shape)
    first_x, weights_x = _cubic_weights(cols, pitch)
    along_x = [np.ascontiguousarray(sum(node[:, first_x + j] * weights_x[:, j] for j in range(4)))
               for node in nodes]
    grid = (along_x, rough, first_x)
    with _NODE_LOCK:
        _NODE_CACHE[key] = grid
        while sum(a.nbytes for g in _NODE_CACHE.values() for a in (*g[0], *g[1:])) \
                > NODE_CACHE_BYTES and len(_NODE_CACHE) > 1:
            _NODE_CACHE.popitem(last=False)
    return grid


def _view_maps(rig: PrismRig, view: int, origin_xy: np.ndarray, canvas: tuple[int, int],
               shape: tuple[int, int]):
    """cv2.remap maps of a canvas (rows, cols) whose pixel (0, 0) is common pixel
    ``origin_xy``, band by band of about MAP_BAND_PIXELS: yields (row slice, map x, map y,
    where no ray gets through), the maps float32 (-10 where no ray).

    Rays are traced exactly on a grid of nodes (one pitch beyond the canvas on each side; the
    pitch is the view's width / MAP_NODES_PER_VIEW, at most 16 px) and the maps between them
    interpolated by separable 4-point Lagrange cubics. The maps are smooth on the scale of the
    view (the error falls as the 4th power of the pitch over the view's width), so this stays
    within the float32 maps' own rounding of tracing every pixel for about 2/pitch^2 of the
    rays: every cell's interpolation is checked against a ray traced through its centre, and
    the pixels of cells that miss it by more than MAP_TOLERANCE_PX, or whose nodes lose their
    ray (total reflection), are traced exactly."""
    rows, cols = canvas
    pitch = map_pitch(shape)
    along_x, rough, first_x = _node_grid(rig, view, origin_xy, canvas, shape)
    gx = np.arange(cols, dtype=np.float64) + origin_xy[0]
    step = max(1, MAP_BAND_PIXELS // cols)
    for r0 in range(0, rows, step):
        band = slice(r0, min(r0 + step, rows))
        first_y, weights_y = _cubic_weights(band.stop, pitch)
        first_y, weights_y = first_y[band], weights_y[band]
        shape_band = (band.stop - band.start, cols)
        mx, my = np.empty(shape_band, np.float32), np.empty(shape_band, np.float32)
        exact, bad = np.empty(shape_band, bool), np.zeros(shape_band, bool)
        if band_maps(along_x[0], along_x[1], first_y, weights_y, first_x, rough, mx, my, exact):
            ys, xs = np.nonzero(exact)
            tx, ty = common_to_view(rig, view, gx[xs], ys + (r0 + origin_xy[1]), shape)
            bad[ys, xs] = ~(np.isfinite(tx) & np.isfinite(ty))
            mx[ys, xs], my[ys, xs] = np.where(bad[ys, xs], -10, tx), np.where(bad[ys, xs], -10, ty)
        yield band, mx, my, bad


def rig_axis_and_field(rig: PrismRig, view_shape: tuple[int, int], origins: np.ndarray,
                       offset: np.ndarray, covered: np.ndarray):
    """Panorama pixel [row, col] of the main lens's optical axis, and the panorama's angular
    field {"x", "y"} (deg): the covered span along the row (column) through each view's centre,
    the widest of them (the prisms bend the views' outer edges, so the span depends on the line).
    ``covered`` (rows', cols') marks the panorama pixels with data; ``offset`` maps view-0
    pixels to panorama pixels."""
    rows, cols = view_shape
    shift = -origins[0] + [offset[1, 2], offset[0, 2]]  # common -> panorama (view 0 reference)
    axis = np.array([(rows - 1) / 2, (cols - 1) / 2]) + shift
    pix = rig.sensor_mm / cols
    dist = optics_prism.image_distance_mm(rig.focal_mm, rig.object_distance_mm)
    field_deg: dict = {"x": None, "y": None}
    for k in range(len(rig.views)):
        cx, cy = view_to_common(rig, k, np.array([(cols - 1) / 2]), np.array([(rows - 1) / 2]),
                                view_shape)
        centre = np.array([cy[0], cx[0]]) + shift
        for name, line, c in (("x", covered[int(round(centre[0])), :], axis[1]),
                              ("y", covered[:, int(round(centre[1]))], axis[0])):
            idx = np.nonzero(line)[0]
            if idx.size == 0:
                continue
            lo, hi = idx.min() - 0.5 - c, idx.max() + 0.5 - c  # pixel edges
            span = float(np.degrees(np.arctan(hi * pix / dist) - np.arctan(lo * pix / dist)))
            field_deg[name] = span if field_deg[name] is None else max(field_deg[name], span)
    return axis.tolist(), field_deg
