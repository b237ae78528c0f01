"""``stitch``: 2 or 4 overlapping views -> one extended-FOV panorama and a :class:`StitchReport`.

The method, step by step: validate the views; remove a known radial distortion, or resample the
views of a prism rig into its common undistorted frame; register each neighbour pair (or reuse a
saved transform) and solve one transform per view; warp every view onto the panorama canvas;
match exposure from the overlaps; trim the canvas to what the views cover; blend the seams;
measure the local shifts left in every overlap.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

from plenocli.progress import step
from plenocli.stitch import compose, verify
from plenocli.stitch.coarse import fine_windows
from plenocli.stitch.errors import StitchError
from plenocli.stitch.ncc import ncc
from plenocli.stitch.nodata import NoData
from plenocli.stitch.overlaps import match_gains, measure_overlaps
from plenocli.stitch.registration import auto_layout, check_transform, priors, register
from plenocli.stitch.rig import PrismRig, canvases, rig_axis_and_field, rig_strips
from plenocli.stitch.translation import estimate_translation
from plenocli.stitch.views import (
    BLENDS,
    LAYOUTS,
    MODELS,
    as_view_stack,
    fill_nan_channels,
    luminance,
    neighbour_pairs,
    translation_matrix,
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


# BLAS on one thread: the stitch's products are small or tall and thin (normal equations,
# phase correlations), where OpenBLAS's second thread costs more than it gives on a shared
# machine (the bench's 2 x 2 homography: a third less CPU and wall time)
@threadpool_limits.wrap(limits=1, user_api="blas")
def stitch(views: np.ndarray | Sequence[np.ndarray], *, layout: str = "auto",
           model: str = "auto", distortion_k1: float = 0.0, transform: dict | None = None,
           blend: str = "feather", match_gain: bool = True, max_overlap: float = 0.7,
           min_overlap_px: int = 16, min_correlation: float = 0.4, rig: PrismRig | None = None,
           overlap: float | None = None, overlap_tolerance: float = 0.1,
           tolerance_px: float | None = None, out: Callable[..., Callable] | None = None,
           claim: tuple[str, str] | None = None, named: Sequence[str] | None = None,
           levels: Sequence[float] | None = None, estimated: Sequence | None = None
           ) -> tuple[np.ndarray, StitchReport]:
    """Stitch 2 or 4 overlapping views into one extended-FOV panorama.

    Parameters
    ----------
    views : (V, rows, cols) or (V, C, rows, cols) array, or a sequence of V equal arrays;
        V = 2 (1x2 or 2x1) or 4 (2 x 2, row-major). NaN = no data (see :mod:`.nodata`).
    layout : "1x2", "2x1", "2x2" or "auto" (4 views -> 2x2; 2 views -> the direction whose
        overlap correlates best, or the rig's).
    model : "translation", "homography" or "auto" (a saved transform's own, else translation).
    distortion_k1 : known radial distortion removed first (:func:`~.views.undistort`); 0: none.
    transform : a previous report's ``transform``, reapplied instead of registering the views.
    blend : "feather" (weights = distance to the view's edge) or "multiband".
    match_gain : match per-view, per-channel exposure from the overlaps (view 0 is the reference).
    max_overlap, min_overlap_px, min_correlation : search limits (estimate_translation).
    rig : the prism rig (one entry per view): views are placed through its undistorted common
        frame, each pair searched within ``tolerance_px`` (default 5 % of the view, >= 8 px).
    overlap, overlap_tolerance : without a rig, the expected overlap (fraction of the view
        along the stitching direction) and the tolerance on it (same unit).
    out : given the shape (C, rows', cols'), the function ``write_rows(rows, pixels)`` taking
        each band of the panorama once final (e.g. into a file; the panorama is then None).
    claim : (what placed the views, what to do) as the refusal says them when the views do not
        line up at a seam (:mod:`plenocli.stitch.verify`, before the blend); by default the
        transform, the rig or the registration (:func:`plenocli.stitch.verify.default_claim`).
    named : the views' names when they gave ``layout`` (L,R: 1x2): a pair that registers only
        the other way is then not told to take another --layout, which the names rule out.
    levels : each view's median before it became ``views`` where that lost its sign (a Bayer
        mosaic demosaiced clips negatives to 0): a refused negated view is named from them.
    estimated : per view, its channels not measured (colour.highlights.Estimated): no gains.

    Returns (panorama, :class:`StitchReport`): the panorama (rows', cols') float32, or (C, rows',
    cols') for colour views, NaN where no view covers it.
    """
    stack, colour = as_view_stack(views)
    n_views, n_chan, rows, cols = stack.shape
    model = _check_options(n_views, layout=layout, model=model, blend=blend, overlap=overlap,
                           tolerance=overlap_tolerance, k1=distortion_k1, transform=transform)
    rig, origins, frame_shape, layout = _rig_frames(_rig_of(rig, transform, n_views),
                                                    (rows, cols), layout, n_views)
    search = dict(max_overlap=max_overlap, min_overlap_px=min_overlap_px,
                  min_correlation=min_correlation, overlap=overlap,
                  overlap_tolerance=overlap_tolerance, tolerance_px=tolerance_px)
    stack = (nodata := NoData(stack, estimated)).measured(stack)  # isolated NaN: nodata.py
    step("registering the views")
    with nodata.too_few_known():
        transforms, layout, source, pair_info, closure = _transforms(
            stack, transform, layout, model, origins, search, view_shape=(rows, cols),
            frame_shape=frame_shape, k1=distortion_k1, rig=rig, named=named, levels=levels)
    pairs = neighbour_pairs(layout)
    frame_to_ref = list(transforms) if rig is None else [
        t @ translation_matrix(-o[0], -o[1]) for t, o in zip(transforms, origins, strict=True)]
    claim = claim or verify.default_claim(transform=transform is not None, rig=rig is not None)
    panorama, covered, offset, gains, fits, areas = _composite(
        stack, frame_to_ref, pairs, match_gain=match_gain, blend=blend, k1=distortion_k1,
        rig=rig, out=out, claim=claim, levels=levels, nodata=nodata)
    pair_info, measured = _pair_report(pair_info, pairs, fits, areas)
    rig_dict, axis_px, field_deg = _rig_report(rig, (rows, cols), origins, offset, covered)
    return (panorama if colour or panorama is None else panorama[0]), StitchReport(
        model=model, layout=layout, n_views=n_views, channels=n_chan if colour else 1,
        view_shape=[rows, cols], distortion_k1=distortion_k1, blend=blend, rig=rig_dict,
        canvas_shape=list(frame_shape) if rig is not None else None,
        canvas_origins_px=origins.tolist() if origins is not None else None,
        axis_px=axis_px, field_deg=field_deg, transform_source=source,
        transform={"model": model, "layout": layout, "view_shape": [rows, cols],
                   "distortion_k1": distortion_k1, "rig": rig_dict,
                   "view_to_reference": [t.tolist() for t in transforms]},
        shifts_px=[[float(t[1, 2]), float(t[0, 2])] for t in transforms],
        pairs=pair_info, gains=gains.tolist(),
        residual_px=float(np.sqrt(np.mean(np.square(measured)))) if measured else None,
        closure_px=closure, panorama_shape=list(covered.shape),
        origin_px=[float(offset[1, 2]), float(offset[0, 2])],
        coverage_fraction=np.count_nonzero(covered) / covered.size)


def _rig_report(rig: PrismRig | None, shape: tuple[int, int], origins, offset, covered):
    """The rig (as a dict), the panorama's optical axis and angular field: None without one."""
    if rig is None:
        return None, None, None
    return rig.to_dict(), *rig_axis_and_field(rig, shape, origins, offset, covered)


def _pair_report(pair_info: list[dict] | None, pairs, fits: list, areas: list
                 ) -> tuple[list[dict], list[float]]:
    """Each pair's registration figures (a given transform's pairs: only named) with how well
    its seam lines up (:class:`plenocli.stitch.verify.SeamFit`: ``residual_px``,
    ``seam_correlation``; None where too narrow to measure) and its overlap area; and the
    residuals measured."""
    if pair_info is None:
        pair_info = [{"views": [a, b], "direction": d} for a, b, d in pairs]
    for info, fit, area in zip(pair_info, fits, areas, strict=True):
        info.update(residual_px=None if fit is None else fit.residual_px,
                    seam_correlation=None if fit is None else fit.correlation,
                    overlap_px_area=area)
    return pair_info, [fit.residual_px for fit in fits if fit is not None]


def _transforms(stack: np.ndarray, transform: dict | None, layout: str, model: str,
                origins: np.ndarray | None, search: dict, *, view_shape: tuple[int, int],
                frame_shape: tuple[int, int], k1: float, rig: PrismRig | None,
                named: Sequence[str] | None = None, levels: Sequence[float] | None = None):
    """View -> view 0 transforms (with a rig: between the views' canvases of ``frame_shape``):
    registered (priors from the rig or the expected overlap), or a saved transform checked
    against the input views' ``view_shape``. Returns them, the layout, their source, the
    per-pair reports (None for a saved transform) and the closure; a negated view named by
    its ``levels`` when the views are refused (:func:`_sign_hint`)."""
    n_views = stack.shape[0]
    signs = functools.partial(_sign_hint, stack, levels)
    with signs():  # a negated Bayer view is demosaiced to 0: a constant view
        luma = luminance(stack)
    if transform is not None:
        with signs():
            transforms, layout, source = check_transform(
                transform, n_views, view_shape, model, k1=k1, rig=rig,
                frame_shape=frame_shape, max_overlap=search["max_overlap"])
        return transforms, layout, source, None, None
    limits = {k: search[k] for k in ("max_overlap", "min_overlap_px", "min_correlation")}
    overlap, overlap_tolerance = search["overlap"], search["overlap_tolerance"]
    if k1:
        luma = np.stack([undistort(v, k1) for v in luma])
    forced = layout if rig is None and n_views == 2 and layout != "auto" else None
    restricted = overlap is not None and rig is None and n_views == 2  # by the user's --overlap
    hint = functools.partial(_overlap_hint, luma if restricted else None, search, layout)
    if layout == "auto" and n_views == 4:
        layout = "2x2"
    elif layout == "auto":
        with signs(), hint(), _prism_hint(rig, luma):
            layout = auto_layout(luma, limits, overlap, overlap_tolerance)
    tolerance = search["tolerance_px"]
    if rig is not None and tolerance is None:  # the default of the whole canvases, not strips
        tolerance = max(8.0, 0.05 * max(frame_shape))
    expected = priors(layout, frame_shape, origins, overlap, overlap_tolerance, tolerance)
    if rig is not None:
        _check_rig_layout(expected, layout, frame_shape)
    windows, across = expected, dict.fromkeys(expected)
    if rig is None:
        def images(a, b, _):
            return luma[a], luma[b], (0, 0), (0, 0)
    else:
        if model == "translation":
            with signs():
                windows, across = fine_windows(luma, rig, origins, layout, expected, limits)

        def images(a, b, direction):
            return rig_strips(luma, rig, origins, frame_shape, a, b, direction,
                              windows[(a, b)], across[(a, b)])
    with signs(), hint(), \
            _layout_hint(forced, luma, limits, overlap, overlap_tolerance, named), \
            _prism_hint(rig, luma):
        transforms, pair_info, closure = register(images, n_views, frame_shape, layout, model,
                                                  limits, windows)
    for info in pair_info:  # the report keeps the rig's own prediction
        prior = expected[tuple(info["views"])][0]
        if prior is not None:
            info["expected_shift_px"] = list(prior)
    return transforms, layout, "estimated", pair_info, closure


WAYS = {"1x2": "side by side", "2x1": "one above the other"}


@contextlib.contextmanager
def _overlap_hint(luma: np.ndarray | None, search: dict, layout: str):
    """Two views not found within the user's --overlap: when a search without it finds them,
    say by how much they overlap (not "a periodic scene?", nor "give --overlap")."""
    try:
        yield
    except StitchError:
        if luma is None:
            raise
        limits = {k: search[k] for k in ("max_overlap", "min_overlap_px", "min_correlation")}
        found = []
        for name, direction in (("1x2", "h"), ("2x1", "v")):
            if layout in ("auto", name):
                with contextlib.suppress(StitchError):
                    info = estimate_translation(luma[0], luma[1], direction=direction,
                                                **limits)[2]
                    found.append((info["correlation"], name, info["overlap_fraction"]))
        if not found:
            raise
        _, name, fraction = max(found)
        raise StitchError(f"views 0 and 1 show no overlap within --overlap "
                          f"{search['overlap']:g} +- {search['overlap_tolerance']:g} of the view; "
                          f"searched without it they overlap by {fraction:.2f} {WAYS[name]}: "
                          f"give --overlap {fraction:.2f}, or leave it out") from None


@contextlib.contextmanager
def _layout_hint(forced: str | None, luma: np.ndarray, limits: dict, overlap: float | None,
                 overlap_tolerance: float, named: Sequence[str] | None = None):
    """Two views given a --layout they do not have: when the pair is not found that way but
    registers the other way, say so (not "no overlap", nor "a periodic scene?")."""
    try:
        yield
    except StitchError:
        if forced not in ("1x2", "2x1"):
            raise
        try:
            found = auto_layout(luma, limits, overlap, overlap_tolerance)
        except StitchError:
            found = None
        if found is None or found == forced:
            raise
        if named:  # the names place them: the other way is a chance or ghost match
            raise StitchError(f"views 0 and 1 do not register {WAYS[forced]}, where their "
                              f"names {','.join(named)} place them (they match only "
                              f"{WAYS[found]}, which the names rule out): check that both "
                              "are views of one scene, in one unit") from None
        raise StitchError(f"views 0 and 1 show no overlap {WAYS[forced]} (--layout {forced}) "
                          f"but register {WAYS[found]}: give --layout {found}, or auto") from None


@contextlib.contextmanager
def _sign_hint(views: np.ndarray, levels: Sequence[float] | None = None):
    """A view not found where another is seen, whose levels are mostly below zero where the
    other's are above: a negated view (a sign lost in a subtraction) does not correlate with
    the scene, nor lines up with it where a transform or a rig places it, whatever the layout
    or overlap the other hints would advise. ``levels`` (see :func:`stitch`) stand for the
    views' own medians where those lost their sign."""
    try:
        yield
    except StitchError as err:
        medians = list(levels) if levels is not None else [
            float(np.nanmedian(v)) if np.isfinite(v).any() else 0.0 for v in views]
        low, high = int(np.argmin(medians)), int(np.argmax(medians))
        if not (medians[high] > 0 and medians[low] <= -0.5 * medians[high]):
            raise
        raise StitchError(f"view {low}'s levels are mostly below zero (median "
                          f"{medians[low]:.3g}, view {high}'s {medians[high]:.3g}): light is "
                          "not negative, and a negated view matches none of the others "
                          "(registered, or placed by a transform or a rig); check how view "
                          f"{low} was made") from err


@contextlib.contextmanager
def _prism_hint(rig: PrismRig | None, luma: np.ndarray):
    """An overlap not found gets the way out: without a rig, views that show one field (a
    stereo or dual-pixel pair: nothing to extend), or views seen through prisms; with one, the
    rig or the views' order."""
    try:
        yield
    except StitchError as err:
        not_found = "no reliable overlap" in str(err) or "no overlap" in str(err)
        if rig is not None and not_found:
            raise StitchError(f"{err}; through the rig: it may not be this capture's rig "
                              "(another prism, lens or focus), or the views are not in the "
                              "rig's order (--views)") from err
        if rig is None and not_found:
            if _same_field(luma):
                raise StitchError(f"{err}; the views show one field, shifted by a few pixels "
                                  "at most (a stereo or dual-pixel pair, not views through "
                                  "prisms): there is nothing to extend; plenocli depth "
                                  "measures their disparity") from err
            raise StitchError(f"{err}; views seen through prisms can hide their overlap (the "
                             "prisms' distortion bends it): pass the rig (--rig RIG.yaml, see "
                             "configs/rigs/)") from err
        raise


SAME_FIELD = 0.5  # correlation of the views' reduced texture, unshifted: they show one field
SAME_FIELD_REDUCE = 8  # a few pixels of disparity are a fraction of a pixel reduced this much


def _same_field(luma: np.ndarray) -> bool:
    """Whether the first two views' textures, reduced 8 x, correlate unshifted: the search for
    an overlap reaches 70 % of the view at most, so views of one field are never matched."""
    rows, cols = luma.shape[1:]
    size = (max(8, cols // SAME_FIELD_REDUCE), max(8, rows // SAME_FIELD_REDUCE))
    small = [cv2.resize(np.nan_to_num(v.astype(np.float32)), size, interpolation=cv2.INTER_AREA)
             for v in luma[:2]]
    a, b = (v - cv2.GaussianBlur(v, (0, 0), 4.0) for v in small)
    return bool(ncc(a.ravel(), b.ravel()) >= SAME_FIELD)


def _check_rig_layout(expected: dict, layout: str, frame_shape: tuple[int, int]) -> None:
    """Refuse a rig whose predicted view positions do not make the layout: each view after its
    neighbour (right of it, or below), overlapping it, and further along the layout's direction
    than across it (a side-by-side rig is not a 2x1 layout)."""
    for a, b, direction in neighbour_pairs(layout):
        (dy, dx), _ = expected[(a, b)]
        along, size = (dx, frame_shape[1]) if direction == "h" else (dy, frame_shape[0])
        across = dy if direction == "h" else dx
        where = "right of" if direction == "h" else "below"
        if abs(across) > abs(along):
            placed = "below" if direction == "h" else "right of"
            raise StitchError(f"--layout {layout} contradicts the rig: it puts view {b} {placed} "
                             f"view {a}, not {where} it; drop --layout (the rig sets it)")
        if not 0 < along < size:
            raise StitchError(f"the rig puts view {b} {along:.0f} px from view {a} along the "
                             f"layout {layout} (views {size} px long), so not {where} it with an "
                             "overlap; list the views in the rig's order (--views) or fix the "
                             "rig's prisms and pupils")


def _composite(stack: np.ndarray, frame_to_ref: list[np.ndarray], pairs: list, *,
               match_gain: bool, blend: str, k1: float, rig: PrismRig | None, nodata: NoData,
               claim: tuple[str, str], out, levels: Sequence[float] | None = None):
    """The blended panorama (C, rows', cols') trimmed to what the views cover, the pixels they
    cover, the reference -> panorama translation, the per-view, per-channel gains, and per pair
    how well its seam lines up (:func:`plenocli.stitch.verify.seam_fits`) and its overlap area;
    refused before the blend where the seams do not line up (``claim``: see :func:`stitch`; a
    negated view named by its ``levels``). ``stack`` is ``nodata``'s measured views: when
    they are its copy, their holes are filled in place for the blend."""
    maps, boxes, offset, shape = compose.place(frame_to_ref, stack.shape[-2:], k1=k1, rig=rig)
    step("checking the seams")
    fits = verify.seam_fits(stack, maps, boxes, pairs)
    with nodata.too_few_known(), _sign_hint(stack, levels):
        verify.check_fits(fits, pairs, what=claim[0], remedy=claim[1])
    holes = nodata.holes()
    filled = [view if h is None else fill_nan_channels(view, in_place=nodata.copied)
              for view, h in zip(stack, holes, strict=True)]
    overlaps = measure_overlaps(filled, maps, boxes, holes, pairs, nodata.estimated)
    gains = np.ones(stack.shape[:2])
    if match_gain:
        gains = match_gains(overlaps, pairs, stack)
    areas = [0 if overlap is None else overlap.area for overlap in overlaps]
    del overlaps
    box = compose.covered_box(maps, boxes, holes)
    if box is None:
        raise StitchError("the views cover no pixel of the panorama; check the transform")
    offset = translation_matrix(-box[0].start, -box[1].start) @ offset
    pano_shape = (stack.shape[1], box[0].stop - box[0].start, box[1].stop - box[1].start)
    panorama = None if out else np.empty(pano_shape, np.float32)
    write_rows = out(pano_shape) if out else functools.partial(_write_rows, panorama)
    if blend == "multiband":
        whole = compose.multiband_blend(filled, maps, boxes, holes, gains, shape,
                                        nodata.estimated)[
            (slice(None),) + box]
        covered = np.isfinite(whole).all(axis=0)
        write_rows(slice(0, pano_shape[1]), whole)
    else:
        covered = compose.blend(filled, *compose.crop(maps, boxes, box), holes, gains, pano_shape,
                                write_rows, nodata.estimated)
    return panorama, covered, offset, gains, fits, areas


def _write_rows(panorama: np.ndarray, rows: slice, pixels: np.ndarray) -> None:
    panorama[:, rows] = pixels


def _check_options(n_views: int, *, layout: str, model: str, blend: str, overlap: float | None,
                   tolerance: float, k1: float, transform: dict | None) -> str:
    """Refuse options out of their ranges; the model to place the views with."""
    if not (np.isfinite(k1) and -1 < k1 <= 1):
        raise ValueError(f"distortion k1 must be a finite number in (-1, 1], got {k1}")
    if model != "auto" and model not in MODELS:
        raise ValueError(f"model must be 'auto' or one of {MODELS}, got {model!r}")
    if blend not in BLENDS:
        raise ValueError(f"blend must be one of {BLENDS}, got {blend!r}")
    if layout != "auto" and layout not in LAYOUTS:
        raise ValueError(f"layout must be 'auto' or one of {sorted(LAYOUTS)}, got {layout!r}")
    if layout != "auto" and LAYOUTS[layout][0] * LAYOUTS[layout][1] != n_views:
        raise StitchError(f"layout {layout} needs {LAYOUTS[layout][0] * LAYOUTS[layout][1]} views, "
                         f"got {n_views}")
    if overlap is not None and not 0 < overlap < 1:
        raise ValueError(f"overlap must be in (0, 1), got {overlap}")
    if not 0 < tolerance < 1:
        raise ValueError(f"overlap_tolerance must be in (0, 1), got {tolerance}")
    return _model_of(model, transform)


def _model_of(model: str, transform: dict | None) -> str:
    """The model to place the views with: a saved transform's (its matrices are of that model,
    as its layout is its own), refused when ``model`` contradicts it; translation by default."""
    if transform is None:
        return "translation" if model == "auto" else model
    saved = transform.get("model") if isinstance(transform, dict) else None
    if saved not in MODELS:
        raise StitchError(f"the transform's model {saved!r} is not one of {', '.join(MODELS)}; "
                          "save a transform with --transform-out")
    if model not in ("auto", saved):
        raise StitchError(f"--model {model} contradicts the transform's model {saved}; drop "
                          "--model (the transform sets it)")
    return saved


def _rig_of(rig: PrismRig | None, transform: dict | None, n_views: int) -> PrismRig | None:
    """The rig given, or the one a saved transform holds; refused unless it has one view per
    input view."""
    if transform is not None and rig is None and transform.get("rig"):
        try:
            rig = PrismRig.from_dict(transform["rig"])
        except ValueError as err:
            raise StitchError(f"the transform's rig is not valid ({err})") from err
    if rig is not None and len(rig.views) != n_views:
        raise StitchError(f"the rig describes {len(rig.views)} views but {n_views} are "
                         "given; list one rig view per input view, in order")
    return rig


def _rig_frames(rig: PrismRig | None, shape: tuple[int, int], layout: str, n_views: int):
    """(rig, its canvases' origins, the frame the views are registered in, layout): the
    views' own frame and no origins without a rig."""
    if rig is None:
        return None, None, shape, layout
    return (rig, *_rig_canvases(rig, shape, layout, n_views))


def _rig_canvases(rig: PrismRig, shape: tuple[int, int], layout: str, n_views: int):
    """The rig's canvases (origins, size) for views of ``shape`` and the layout (for two views,
    "auto" follows the rig's offset between them)."""
    try:
        origins, size = canvases(rig, shape)
    except ValueError as err:
        raise StitchError(f"the rig does not fit these views: {err}") from err
    if layout == "auto":
        d = origins[1] - origins[0]
        layout = "2x2" if n_views == 4 else ("1x2" if abs(d[1]) >= abs(d[0]) else "2x1")
    return origins, size, layout
