"""``stitch``: 2 or 4 overlapping views -> one extended-FOV panorama and a :class:`StitchReport`.

The method, step by step: validate the views; remove a known radial distortion, or resample the
views of a prism rig into its common undistorted frame; register each neighbour pair (or reuse a
saved transform) and solve one transform per view; warp every view onto the panorama canvas;
match exposure from the overlaps; trim the canvas to what the views cover; blend the seams;
measure the local shifts left in every overlap.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from plenocli.errors import InputError
from plenocli.stitch import compose
from plenocli.stitch.quality import overlap_residual
from plenocli.stitch.registration import auto_layout, check_transform, priors, register
from plenocli.stitch.rig import PrismRig, rig_axis_and_field, undistort_views
from plenocli.stitch.views import (
    BLENDS,
    LAYOUTS,
    MODELS,
    as_view_stack,
    fill_nan_channels,
    luminance,
    neighbour_pairs,
    undistort,
)


@dataclass(frozen=True)
class StitchReport:
    """What :func:`stitch` did (``dataclasses.asdict`` gives the JSON report).

    ``transform`` is reusable (``stitch(..., transform=report.transform)``); ``pairs`` holds per
    neighbour pair its shift or homography, overlap, correlation, inliers and ``residual_px``;
    ``origin_px`` is the panorama pixel [row, col] of view 0's pixel (0, 0); with a rig,
    ``canvas_shape`` / ``canvas_origins_px`` describe the common undistorted frame and
    ``axis_px`` / ``field_deg`` the optical axis and angular field of the panorama.
    """

    model: str
    layout: str
    n_views: int
    channels: int
    view_shape: list[int]
    distortion_k1: float
    blend: str
    rig: dict | None
    canvas_shape: list[int] | None
    canvas_origins_px: list | None
    axis_px: list[float] | None
    field_deg: dict | None
    transform_source: str
    transform: dict
    shifts_px: list[list[float]]
    pairs: list[dict]
    gains: list[list[float]]
    residual_px: float | None
    closure_px: float | None
    panorama_shape: list[int]
    origin_px: list[float]
    coverage_fraction: float


def stitch(views: np.ndarray | Sequence[np.ndarray], *, layout: str = "auto",
           model: str = "translation", distortion_k1: float = 0.0,
           transform: dict | None = None, blend: str = "feather", match_gain: bool = True,
           max_overlap: float = 0.7, min_overlap_px: int = 16,
           min_correlation: float = 0.4, rig: PrismRig | None = None,
           overlap: float | None = None, overlap_tolerance: float = 0.1,
           tolerance_px: float | None = None) -> tuple[np.ndarray, StitchReport]:
    """Stitch 2 or 4 overlapping views into one extended-FOV panorama.

    Parameters
    ----------
    views : (V, rows, cols) or (V, C, rows, cols) array, or a sequence of V equal arrays;
        V = 2 (side by side or one above the other) or 4 (2 x 2, row-major). NaN = no data.
    layout : "1x2", "2x1", "2x2" or "auto" (4 views -> 2x2; 2 views -> the direction whose
        overlap correlates best, or the rig's).
    model : "translation" or "homography".
    distortion_k1 : known constant radial distortion removed from every view first (see
        :func:`plenocli.stitch.views.undistort`); 0 = none.
    transform : a previous report's ``transform`` to reapply to views of the same rig instead
        of registering them again.
    blend : "feather" (weights = distance to the view's edge) or "multiband".
    match_gain : match per-view, per-channel exposure from the overlaps (view 0 is the reference).
    max_overlap, min_overlap_px, min_correlation : registration search limits, see
        :func:`plenocli.stitch.translation.estimate_translation`.
    rig : the prism rig (one entry per view): every view is first resampled into the common
        undistorted frame (the prisms' constant distortion cancelled), and each pair is searched
        only within ``tolerance_px`` (default 5 % of the view, >= 8 px) of the rig's prediction.
    overlap, overlap_tolerance : without a rig, the expected overlap (fraction of the view
        along the stitching direction) and the tolerance on it (same unit).

    Returns
    -------
    panorama : (rows', cols') float32, or (C, rows', cols') for colour views; NaN where no view
        covers the panorama.
    report : :class:`StitchReport`.
    """
    stack, colour = as_view_stack(views)
    n_views, n_chan, rows, cols = stack.shape
    _check_options(n_views, layout=layout, model=model, blend=blend, overlap=overlap,
                   overlap_tolerance=overlap_tolerance)
    rig = _rig_of(rig, transform, n_views)
    own = bool(distortion_k1) or rig is not None  # a new stack: its NaN are filled in place
    if distortion_k1:
        stack = np.stack([[undistort(ch, distortion_k1) for ch in v] for v in stack])
    origins = None
    if rig is not None:
        stack, origins, layout = _undistort_rig(stack, rig, layout)
    search = dict(max_overlap=max_overlap, min_overlap_px=min_overlap_px,
                  min_correlation=min_correlation, overlap=overlap,
                  overlap_tolerance=overlap_tolerance, tolerance_px=tolerance_px)
    transforms, layout, source, pair_info, closure = _transforms(
        luminance(stack), transform, layout, model, origins, search, view_shape=(rows, cols))
    pairs = neighbour_pairs(layout)
    canvas_shape = list(stack.shape[-2:])
    panorama, layers, offset, gains, residuals = _composite(
        stack, transforms, pairs, match_gain=match_gain, blend=blend, fill_in_place=own)
    del stack
    pair_info = _pair_report(pair_info, pairs, residuals)
    measured = [res for res, _ in residuals if res is not None]
    covered = np.isfinite(panorama).all(axis=0)
    axis_px = field_deg = None
    if rig is not None:
        axis_px, field_deg = rig_axis_and_field(rig, (rows, cols), origins, offset, covered)
    rig_dict = rig.to_dict() if rig is not None else None
    report = StitchReport(
        model=model, layout=layout, n_views=n_views, channels=n_chan if colour else 1,
        view_shape=[rows, cols], distortion_k1=distortion_k1, blend=blend, rig=rig_dict,
        canvas_shape=canvas_shape if rig is not None else None,
        canvas_origins_px=origins.tolist() if origins is not None else None,
        axis_px=axis_px, field_deg=field_deg, transform_source=source,
        transform={"model": model, "layout": layout, "view_shape": [rows, cols],
                   "distortion_k1": distortion_k1, "rig": rig_dict,
                   "view_to_reference": [t.tolist() for t in transforms]},
        shifts_px=[[float(t[1, 2]), float(t[0, 2])] for t in transforms],
        pairs=pair_info, gains=gains.tolist(),
        residual_px=float(np.sqrt(np.mean(np.square(measured)))) if measured else None,
        closure_px=closure, panorama_shape=list(panorama.shape[1:]),
        origin_px=[float(offset[1, 2]), float(offset[0, 2])],
        coverage_fraction=float((layers.total > 0).mean()))
    return (panorama if colour else panorama[0]), report


def _pair_report(pair_info: list[dict] | None, pairs, residuals) -> list[dict]:
    """Each pair's registration figures with its residual; a given transform's pairs are only
    named."""
    if pair_info is None:
        return [{"views": [a, b], "direction": d} for a, b, d in pairs]
    for info, (res, area) in zip(pair_info, residuals, strict=True):
        info.update(residual_px=res, overlap_px_area=area)
    return pair_info


def _transforms(luma: np.ndarray, transform: dict | None, layout: str, model: str,
                origins: np.ndarray | None, search: dict, *, view_shape: tuple[int, int]):
    """View -> view 0 transforms: registered (priors from the rig or the expected overlap),
    or a saved transform checked against the input views' ``view_shape``. Returns them, the
    layout, their source, the per-pair reports (None for a saved transform) and the closure."""
    n_views, rows, cols = luma.shape  # with a rig: the common frame's canvases
    if transform is not None:
        transforms, layout, source = check_transform(transform, n_views, view_shape, model)
        return transforms, layout, source, None, None
    limits = {k: search[k] for k in ("max_overlap", "min_overlap_px", "min_correlation")}
    overlap, overlap_tolerance = search["overlap"], search["overlap_tolerance"]
    if layout == "auto":
        layout = "2x2" if n_views == 4 else auto_layout(luma, limits, overlap, overlap_tolerance)
    expected = priors(layout, (rows, cols), origins, overlap, overlap_tolerance,
                      search["tolerance_px"])
    transforms, pair_info, closure = register(luma, layout, model, limits, expected)
    return transforms, layout, "estimated", pair_info, closure


def _composite(stack: np.ndarray, transforms: list[np.ndarray], pairs: list, *,
               match_gain: bool, blend: str, fill_in_place: bool):
    """The blended panorama (C, rows', cols'), the views' layers on it, the view-0 -> panorama
    translation, the per-view, per-channel gains and per pair (residual px, overlap area).
    The views' NaN are filled (nearest value) in ``stack`` itself when ``fill_in_place``."""
    valid = [np.isfinite(view).all(axis=0) for view in stack]
    filled = [fill_nan_channels(view, in_place=fill_in_place) for view in stack]
    offset, pano_shape = compose.canvas(transforms, stack.shape[-2:])
    layers = compose.place_views(valid, transforms, offset, pano_shape)
    del valid
    layers, offset = compose.trim_to_coverage(layers, offset)
    overlaps = compose.pair_overlaps(layers, pairs)
    gains = np.ones(stack.shape[:2])
    if match_gain:
        gains = compose.match_gains(filled, layers, pairs, overlaps)
    residuals = []
    for (a, b, _), overlap in zip(pairs, overlaps, strict=True):
        if overlap is None:
            residuals.append((None, 0))
            continue
        region, both = overlap
        luma_a = compose.overlap_luminance(filled, layers, a, region, gains)
        luma_b = compose.overlap_luminance(filled, layers, b, region, gains)
        residuals.append((overlap_residual(luma_a, luma_b, both), int(both.sum())))
    return compose.blend(filled, layers, gains, blend), layers, offset, gains, residuals


def _check_options(n_views: int, *, layout: str, model: str, blend: str,
                   overlap: float | None, overlap_tolerance: float) -> None:
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    if blend not in BLENDS:
        raise ValueError(f"blend must be one of {BLENDS}, got {blend!r}")
    if layout != "auto" and layout not in LAYOUTS:
        raise ValueError(f"layout must be 'auto' or one of {sorted(LAYOUTS)}, got {layout!r}")
    if layout != "auto" and LAYOUTS[layout][0] * LAYOUTS[layout][1] != n_views:
        raise InputError(f"layout {layout} needs {LAYOUTS[layout][0] * LAYOUTS[layout][1]} views, "
                         f"got {n_views}")
    if overlap is not None and not 0 < overlap < 1:
        raise ValueError(f"overlap must be in (0, 1), got {overlap}")
    if not 0 < overlap_tolerance < 1:
        raise ValueError(f"overlap_tolerance must be in (0, 1), got {overlap_tolerance}")


def _rig_of(rig: PrismRig | None, transform: dict | None, n_views: int) -> PrismRig | None:
    """The rig given, or the one a saved transform holds; refused unless it has one view per
    input view."""
    if transform is not None and rig is None and transform.get("rig"):
        try:
            rig = PrismRig.from_dict(transform["rig"])
        except ValueError as err:
            raise InputError(f"the transform's rig is not valid ({err})") from err
    if rig is not None and len(rig.views) != n_views:
        raise InputError(f"the rig describes {len(rig.views)} views but {n_views} are "
                         "given; list one rig view per input view, in order")
    return rig


def _undistort_rig(stack: np.ndarray, rig: PrismRig, layout: str):
    """The views in the rig's common undistorted frame, their canvases' origins and the
    layout (for two views, "auto" follows the rig's offset between them)."""
    try:
        stack, origins = undistort_views(stack, rig)
    except ValueError as err:
        raise InputError(f"the rig does not fit these views: {err}") from err
    if layout == "auto":
        d = origins[1] - origins[0]
        layout = "2x2" if len(stack) == 4 else ("1x2" if abs(d[1]) >= abs(d[0]) else "2x1")
    return stack, origins, layout
