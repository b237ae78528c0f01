"""Stage ``depth``: a lenslet frames TIFF + lens grid -> g and confidence on the refocus grid,
or dual/quad-pixel views -> disparity and confidence (docs/depth.md)."""

from __future__ import annotations

from functools import partial

import numpy as np

from plenocli.depth import lenslet, metric, quad, views
from plenocli.depth.directions import check_directions
from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.io.framing import frame_grid
from plenocli.io.preview import write_depth_png
from plenocli.model.numbers import decimal
from plenocli.model.provenance import stage_record
from plenocli.model.views import ViewNames, split_colour_page, view_of
from plenocli.pipeline.fits import (
    beyond_grid,
    centred_on,
    check_fits,
    warn_unchecked,
    weak_match,
)
from plenocli.progress import log, shown

DUAL = ["A", "B"]
QUAD = ["S00", "S01", "S10", "S11"]
MIN_KNOWN = 0.25  # fraction of the frame a depth map must measure
MIN_CLEAR = 0.01  # fraction of dual/quad-pixel views that must match clearly (see _views)
MIN_CONSISTENT = 0.6  # share of those clear matches that must agree with the ones around them


def parse_range(text: str) -> tuple[float, float]:
    """MIN:MAX -> (min, max), ValueError with the usage otherwise."""
    try:
        lo, hi = (decimal(v) for v in str(text).split(":"))
    except ValueError as err:
        raise ValueError(f"g range must be MIN:MAX (e.g. 2:8, Galilean -8:-2), got {text!r}") \
            from err
    return lenslet.check_range((lo, hi))


def run(input: str, output: str, *, grid: str | None = None, s: float = 0.2,
        g: str = "2:8", min_confidence: float = 0.1, max_disparity: float = 4.0,
        camera: str | None = None, preview: str | None = None) -> None:
    """Depth of ``input``: lenslet frames with ``grid``, else dual/quad-pixel views; with
    ``camera`` (lenslet) a depth_m page."""
    try:
        g_range = parse_range(g)
    except ValueError as err:
        raise ConfigError(f"--g: {err}") from err
    if camera and not grid:
        raise ConfigError("--camera gives metres from g: it needs lenslet frames and --grid")
    optics = _camera(camera) if camera else None
    data, meta = tiffio.read_image(input)
    params = dict(grid=grid, s=s, g=g, min_confidence=min_confidence,
                  max_disparity=max_disparity, camera=camera)
    if grid:
        _check_not_views(input, data, meta)
        pages, names, info = _lenslet(input, grid, data, meta, s, g_range, min_confidence)
        if optics is not None:
            pages.insert(1, metric.distance_m(pages[0], optics))
            names.insert(1, "depth_m")
            info["camera"] = {**vars(optics), "mla_distance_mm": optics.mla_distance_mm,
                              "formula": "z = F b / (b - F), b = b_L + g B"}
    else:
        pages, names, info = _views(input, data, meta, max_disparity)
    _check_known(pages[0], f"g in --g {g}" if grid else
                 f"disparity within --max-disparity {max_disparity:g}")
    if grid:
        try:
            check_directions(info["g_by_direction"])
        except ValueError as err:
            raise InputError(f"depth: {err}") from err
    record = stage_record("depth", params, {"input": input, "grid": grid, "camera": camera})
    stack = np.stack(pages).astype(np.float32)
    out_meta = tiffio.derived_meta(
        meta, record, views=names, cfa=None, origin=None, black_level=None, white_level=None,
        active_area=[0, 0, stack.shape[1], stack.shape[2]], masked_areas=[], depth=info)
    protect = (input,) + ((grid,) if grid else ()) + ((camera,) if camera else ())
    tiffio.write_image(output, stack, out_meta, protect=protect)
    known = float(np.isfinite(stack[0]).mean())
    log.info("depth: %s -> %s (%s, %d x %d, %.1f %% known)", shown(input), shown(output),
             ", ".join(names), stack.shape[2], stack.shape[1], 100 * known)
    if preview:
        unit = "g" if grid else "disparity (px)"
        write_depth_png(preview, stack[0], stack[-1], label=unit, protect=protect)


def _check_not_views(input, data, meta) -> None:
    """Dual/quad-pixel views are not lenslet frames: with --grid they gave a g map."""
    names = set(ViewNames.of(meta, data.shape[0]).pages)
    if set(DUAL) <= names or set(QUAD) <= names:
        raise InputError(f"{input} holds dual/quad-pixel views, not lenslet frames; drop --grid "
                         "for their disparity")


def _refuse_colour(input, names: list[str]) -> None:
    """Colour pages of the views depth measures (S00.R ...: sai of an RGB image) are refused as
    what they are; depth measures grey views (a raw's, Bayer or not) only."""
    found = {view_of(n) for n in names if split_colour_page(n)}
    for wanted, what in ((QUAD, "quad-pixel SAIs"), (DUAL, "dual-pixel views")):
        if set(wanted) <= found:
            raise InputError(f"{input} holds colour {what} {', '.join(wanted)} (pages "
                             f"{wanted[0]}.R ... {wanted[-1]}.B); depth measures grey views "
                             "only: give the views of a grey or Bayer capture (sai or bias of "
                             "its raw frames)")


def _check_known(values, searched: str, no_data: float = 0.0) -> None:
    """Refuse a map whose pixels are mostly unknown: there the best match lay at a bound of
    the search (no minimum) or nothing matched (no texture); the few left are not a map.
    ``no_data``: the share of pixels without data (NaN in a view), said when there are any."""
    known = float(np.isfinite(values).mean())
    if known < MIN_KNOWN:
        lost = (f" ({100 * no_data:.1f} % of the frame has no data: NaN pixels in a view)"
                if no_data > 0 else "")
        raise InputError(f"depth: only {100 * known:.1f} % of the frame found a minimum of the "
                         f"match cost with {searched}; the rest lies at a bound of the search "
                         f"or has no texture{lost}: widen the range, or check the input")


def _camera(path: str) -> metric.Camera:
    from plenocli.io.yamlfile import read_side_file

    doc = read_side_file(path, "YAML camera file")
    try:
        return metric.camera_from_dict(doc)
    except ValueError as err:
        raise InputError(f"{path}: {err}") from err


def _lenslet(input, grid_path, data, meta, s, g_range, min_confidence):
    from plenocli import refocus as rf

    framing = frame_grid(grid_path, meta, data.shape[1:], frames_path=input)
    try:
        lenslet.check_measurable(g_range, framing.grid.pitch_px)
    except ValueError as err:  # the grid's to say, not the flag's alone: an input error
        raise ConfigError(f"--g with {grid_path}: {err}") from err
    try:
        rf.check_output_size(framing.shape, s, pages=2)
        grey = lenslet.sensor_grey(framing.crop(data), mosaic=bool(framing.cfa))
        checked = check_fits(grey, framing.grid, grid_path, frames_path=input, for_depth=True,
                             whole=partial(beyond_grid, framing, data,
                                           mosaic=bool(framing.cfa)))
        lens_grid, moved = centred_on(grey, framing.grid, grid_path, refit=True)
        ranges = _type_ranges(grid_path, framing.grid)
        result = lenslet.depth_map(grey, lens_grid, s=s, g_range=g_range,
                                   min_confidence=min_confidence, type_ranges=ranges)
    except ValueError as err:
        raise InputError(f"depth: {err}") from err
    if not checked:
        _check_unchecked_grid(grid_path, result.lenses.confidence)
        warn_unchecked(grid_path)
    if not np.isfinite(result.g).any():
        raise InputError(f"depth: no micro-image of {input} matched its neighbours with "
                         f"confidence >= {min_confidence:g} for g in {g_range[0]:g}:"
                         f"{g_range[1]:g} (the depth lies at a bound of the search or nearer "
                         "than the micro-images measure, or the frame has no texture): widen "
                         "the range (--g; a Galilean camera, with inverted micro-images, "
                         "needs a negative one such as -8:-2), or check the grid")
    lens = result.lenses
    info = {"method": "disparity between neighbouring micro-images, q = 1/g",
            "s": s, "g_range": list(g_range), "min_confidence": min_confidence,
            "crop_sensor_origin": list(framing.sensor_origin),
            "grid_moved_px": None if moved is None else list(moved), "grid_checked": checked,
            "grid_refitted": None if lens_grid.pitch_px == framing.grid.pitch_px else
            {"pitch_px": lens_grid.pitch_px, "angle_deg": float(np.degrees(lens_grid.angle_rad))},
            "usable_radius_px": lens.radius_px, "lenses": int(len(lens.g)),
            "lenses_confident": int(np.sum(lens.confidence >= min_confidence)),
            "type_ranges": None if ranges is None else ranges.tolist(),
            "g_by_direction": None if lens.g_by_direction is None else
            lens.g_by_direction.tolist(),
            "type_ranges_used": lens.ranges_used}
    return [result.g, result.confidence], ["g", "confidence"], info


def _check_unchecked_grid(grid_path: str, confidence: np.ndarray) -> None:
    """A grid the frames cannot check is vouched for by the matches alone (fits.weak_match)."""
    median = float(np.median(confidence))
    if median < lenslet.CLEAR_MATCH:
        raise weak_match("depth", grid_path, median, lenslet.CLEAR_MATCH)


def _type_ranges(grid_path, grid) -> np.ndarray | None:
    """(3, 2) depth range of lens types 0, 1, 2 from a RayCalibData XML grid with types (the
    virtual depths where each type is in focus), else None."""
    from pathlib import Path

    from plenocli.io import raytrix

    if grid.lens_type_of_coset is None or Path(grid_path).suffix.lower() != ".xml":
        return None
    types = {t["id"]: t["depth_range"] for t in raytrix.read_calib(grid_path)["lens_types"]}
    if sorted(types) != [0, 1, 2]:
        return None
    return np.array([types[k] for k in range(3)], float)


def _check_shared_texture(confidence: np.ndarray) -> None:
    """Refuse views that share no texture: where noise alone is matched (a white, a blank
    wall, views that look in different directions) every shift fits about alike and the best
    one is chance, yet most pixels find a minimum. A clear match (confidence >= CLEAR_MATCH, as
    for lenses) is what texture gives: 95 % of the simulator's chart, 8.7 % of the Pixel 4
    scene, 0.22 % of its white sheet, none of a simulated white or of pure noise."""
    clear = float(np.mean(confidence >= lenslet.CLEAR_MATCH))
    if clear < MIN_CLEAR:
        raise InputError(f"depth: the views share no texture to measure a disparity from "
                         f"(only {100 * clear:.2f} % of the pixels match clearly, confidence >= "
                         f"{lenslet.CLEAR_MATCH:g}): a white, a blank surface, views that "
                         "do not see one scene, or a parallax past the search (try a wider "
                         "--max-disparity); nothing was written")


def _refuse_repeats(repeat: np.ndarray, disparity: np.ndarray, max_disparity: float) -> None:
    """Views refused for another reason that lose more pixels to a texture repeating within
    the search (two shifts matching clearly: stripes, a fence, a tiled floor) than they keep
    are refused as such: vertical stripes of 7.3 px searched to 8 were called "no texture",
    the best case for a horizontal baseline, which a search below half their period measures
    (1.000 px); a 5 px sine or checker pattern, 1 px apart, searched to 4 read -4 px."""
    share = float(np.mean(repeat > 0))
    if share < MIN_CLEAR or share <= float(np.isfinite(disparity).mean()):
        return
    apart = float(np.median(repeat[repeat > 0]))
    # below half the repeat already, the parallax itself reaches the repeat's next match
    advice = (f"lower --max-disparity below half the repeat ({apart / 2:g}) if the "
              "disparities are smaller" if max_disparity >= apart / 2 else
              f"the parallax comes near half the repeat ({apart / 2:g}), where no search "
              "can tell the shifts apart")
    raise InputError(f"depth: the views' texture repeats within --max-disparity "
                     f"{max_disparity:g} ({100 * share:.0f} % of the pixels match clearly at "
                     f"two shifts or more, {apart:g} px apart: a periodic texture such as "
                     f"stripes), so which shift is the parallax cannot be told: {advice}; "
                     "nothing was written")


def _check_consistent(disparities: list[np.ndarray], confidence: np.ndarray) -> None:
    """Refuse views whose clear matches scatter: views of two different fields (a prism pair
    looking in different directions) still match clearly here and there by chance, 2-3 % of
    the pixels, but those disparities span the whole search and do not agree with the clear
    matches around them (35-45 % agree within 1 px; a surface's 72-100 %: simulated charts
    and depth bands, the Pixel 4 scene at --max-disparity 4 and 12)."""
    share = min(views.consistent_share(d, confidence) for d in disparities)
    if share < MIN_CONSISTENT:
        raise InputError(f"depth: the views' clear matches do not agree with each other (only "
                         f"{100 * share:.0f} % lie within 1 px of the clear matches around "
                         "them): views that do not see one scene, e.g. prism views looking "
                         "in different directions, or a periodic texture (stripes) repeating "
                         "within --max-disparity: lower it below half the repeat; nothing was "
                         "written")


def _check_data(input, no_data: np.ndarray) -> None:
    """Refuse views left with too few pixels to measure by their NaN pixels (clipped or
    unknown: each costs only itself, but over most of the frame they leave no map), naming
    them, not the search or the texture."""
    share = float(no_data.mean())
    if share > 1 - MIN_KNOWN:
        raise InputError(f"depth: {100 * share:.1f} % of {input}'s pixels have no data in a "
                         f"view (NaN: clipped or unknown, or windows of {views.WINDOW} px "
                         "mostly NaN), leaving too few to measure a disparity map: give views "
                         "with more measured pixels (bias writes NaN where a pixel clipped); "
                         "nothing was written")


def _views(input, data, meta, max_disparity):
    names = list(ViewNames.of(meta, data.shape[0]).pages)
    have = {n: k for k, n in enumerate(names)}
    try:
        if all(n in have for n in QUAD):
            dx, dy = quad.quad_disparity(np.stack([data[have[n]] for n in QUAD]),
                                          max_disparity=max_disparity)
            conf = np.minimum(dx.confidence, dy.confidence)
            pages, out = [dx.disparity, dy.disparity, conf], ["disparity_x", "disparity_y",
                                                              "confidence"]
            repeat = np.maximum(dx.repeat_px, dy.repeat_px)
            no_data = dx.no_data | dy.no_data
        elif all(n in have for n in DUAL):
            d = views.disparity_x(data[have["A"]], data[have["B"]], max_disparity=max_disparity)
            pages, out = [d.disparity, d.confidence], ["disparity", "confidence"]
            repeat = d.repeat_px
            no_data = d.no_data
        else:
            _refuse_colour(input, names)
            raise InputError(f"{input} holds views {', '.join(names)}; depth needs "
                             "dual-pixel views A, B, quad-pixel SAIs S00, S01, S10, S11, or "
                             "lenslet frames with --grid")
    except ValueError as err:
        raise InputError(f"depth: {err}") from err
    _check_data(input, no_data)
    try:
        _check_shared_texture(pages[-1])
        _check_consistent(pages[:-1], pages[-1])
        _check_known(pages[0], f"disparity within --max-disparity {max_disparity:g}",
                     float(no_data.mean()))
    except InputError:
        _refuse_repeats(repeat, pages[0], max_disparity)
        raise
    info = {"method": "shift of B against A along the baseline (+: B's content to the right)",
            "max_disparity": max_disparity, "normalisation": "each view / its Gaussian "
            f"low-pass (sigma {views.FLAT_SIGMA:g} px)", "window_px": views.WINDOW}
    return pages, out, info
