"""Stage ``crosstalk``: masked-pupil white captures (views TIFFs) -> cross-talk JSON + heat map."""

from __future__ import annotations

import json
import math
from functools import partial
from pathlib import Path

import numpy as np

from plenocli import crosstalk as crosstalk_lib
from plenocli.errors import ConfigError, InputError, OptionError
from plenocli.io import tiffio
from plenocli.io.atomic import write_text
from plenocli.io.framing import frame_grid, sensor_image
from plenocli.io.mixingfile import write_mixing
from plenocli.io.preview import write_heat_map
from plenocli.io.views import check_black_subtracted, read_colour_views, read_masked_whites
from plenocli.model.focus import check_mask_width
from plenocli.model.numbers import decimal
from plenocli.model.provenance import json_safe, processing_of, stage_record
from plenocli.model.views import ViewNames, pupil_views, view_of
from plenocli.pipeline.fits import beyond_grid, centred_on, check_fits, warn_unchecked
from plenocli.progress import log, shown


def _intended_index(spec: str | None, names: list[str], path: str) -> int | None:
    if spec is None or spec == "auto":
        return None
    index = ViewNames(tuple(names)).index(spec)
    if index is not None:
        return index
    raise InputError(f"{path}: intended view {spec!r} is not one of {','.join(names)}; pass "
                     "--intended with a view name (or 'auto' for the brightest view)")


def run(inputs: tuple[str, ...] | list[str], output: str, *, views: str | None = None,
        intended: str | None = None, tile: int = 64, preview: str | None = None,
        mask_widths: str | None = None, grid: str | None = None, s: float = 0.2,
        g: float = 4.0, mixing_out: str | None = None) -> None:
    """Measure cross-talk on each input (one masked capture each), or sweep Raytrix mask widths;
    with ``mixing_out`` (one input per pupil part) also the mixing-matrix field M."""
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    if not inputs:
        raise InputError("no input given; pass one views TIFF per masked capture")
    for path in inputs:
        check_black_subtracted(path, tiffio.read_meta(path),
                               "r is a ratio of light: a black level would count as light")
    if grid and not mask_widths:
        raise ConfigError("--grid is used only with --mask-widths (the Raytrix sweep); leave it "
                          "out, or give --mask-widths")
    if mixing_out:
        if mask_widths:
            raise ConfigError("--mixing-out and --mask-widths do not go together; measure the "
                              "mixing on refocused left/right views of masked whites")
        _run_mixing(inputs, output, mixing_out, views=views, intended=intended, tile=tile,
                    preview=preview)
        return
    if mask_widths:
        _run_sweep(inputs, output, intended=intended, tile=tile, mask_widths=mask_widths,
                   grid=grid, s=s, g=g)
        return
    specs = (intended or "auto").split(",")
    if len(specs) not in (1, len(inputs)):
        raise ConfigError(f"--intended has {len(specs)} names for {len(inputs)} inputs; give one "
                          "name, or one per input")
    captures = [_measure(path, views, specs[k if len(specs) > 1 else 0], tile)
                for k, path in enumerate(inputs)]
    params = dict(views=views, intended=intended, tile=tile)
    record = stage_record("crosstalk", params, {"inputs": inputs})
    doc = {"r": max(c["r"] for c in captures), "definition": "max flux on another view / flux "
           "on the intended view, over pixels finite in every view", "captures": captures,
           "provenance": record}
    write_text(output, json.dumps(json_safe(doc), indent=1, allow_nan=False), protect=tuple(inputs))
    if preview:
        titles = [f"{Path(c['input']).stem}: r {100 * c['r']:.1f} % ({c['intended']} intended)"
                  for c in captures]
        write_heat_map(preview, [c["map"] for c in captures], titles, protect=tuple(inputs))
    for c in captures:
        log.info("crosstalk: %s: intended %s, r = %.2f %% (tiles %.2f .. %.2f %%)",
                 shown(c["input"]),
                 c["intended"], 100 * c["r"], 100 * c["map_min"], 100 * c["map_max"])


def _measure(path: str, views: str | None, intended: str | None, tile: int) -> dict:
    """The cross-talk of one masked capture, as its entry in the report. Colour pages of one
    view (A.R, A.G, A.B) are one view: r compares views, over the flux of every colour."""
    capture = read_colour_views(path, pupil_parts(path, views))
    if len(capture.names) < 2:
        raise InputError(f"{path} holds one view ({capture.names[0]}; pages R, G, B are its "
                         "colours): cross-talk compares two or more views (sai, bias, or "
                         "refocus --view left/right output)")
    idx = _intended_index(intended, capture.names, path)
    try:
        res = crosstalk_lib.crosstalk_ratio(capture.data.sum(axis=1), intended=idx,
                                            tile_px=tile, cfa=capture.cfa)
    except ValueError as err:
        raise InputError(f"{path}: {err}") from err
    _check_open_part(path, capture.names[res["intended"]], max(res["r"], res["map_max"]))
    return _capture_entry(path, capture.names, res, tile, capture.cfa)


def pupil_parts(path: str, views: str | None) -> str | None:
    """The views to compare: ``views`` as given; by default a dual-pixel file's A and B, since
    its sum S = A + B is no pupil part of its own (it would count as "another view")."""
    if views is not None:
        named = tiffio.read_meta(path).get("views") or []
        dual = {"A", "B", "S"} <= {view_of(n) for n in named}
        if dual and "S" in {v.strip() for v in views.split(",")}:
            raise ConfigError(f"--views {views}: S is the sum A + B, not a pupil part of its "
                              "own; leave it out (--views A,B)")
        return views
    names = {view_of(n) for n in tiffio.read_meta(path).get("views") or []}
    return "A,B" if {"A", "B", "S"} <= names else None


def _capture_entry(path: str, names: list[str], res: dict, tile: int, cfa: str | None) -> dict:
    """The report's entry for one masked capture (view indices turned into names)."""
    return {
        "input": path, "views": names, "intended": names[res["intended"]],
        "r": res["r"], "r_per_view": {names[j]: v for j, v in res["r_per_view"].items()},
        "map_min": res["map_min"], "map_max": res["map_max"], "tile_px": tile,
        "valid_fraction": res["valid_fraction"], "cfa": cfa,
        "per_colour": {c: {"r": d["r"], "map": d["map"]} for c, d in res["per_colour"].items()},
        "map": res["map"],
    }


def parse_mask_widths(text: str) -> list[float]:
    """"0,1,2,3" -> [0.0, 1.0, 2.0, 3.0]: finite widths >= 0 (px), each once; ValueError with
    the usage otherwise."""
    usage = f"expected comma-separated widths >= 0 px, each once (e.g. 0,1,2,3), got {text!r}"
    try:
        widths = [decimal(w) for w in str(text).split(",")]
    except ValueError as err:
        raise ValueError(usage) from err
    if not all(math.isfinite(w) and w >= 0 for w in widths) or len(set(widths)) < len(widths):
        raise ValueError(usage)
    return widths


def _run_sweep(inputs: list[str], output: str, *, intended: str | None, tile: int,
               mask_widths: str, grid: str | None, s: float, g: float) -> None:
    """Raytrix: refocus left/right views of a half-masked white capture for each mask width."""
    try:
        widths = parse_mask_widths(mask_widths)
    except ValueError as err:
        raise OptionError(f"--mask-widths: {err}") from err
    if len(inputs) != 1:
        raise ConfigError("--mask-widths takes exactly one input: the frames TIFF of a white "
                          "capture with one pupil half masked")
    if not grid:
        raise ConfigError("--mask-widths needs --grid: the lens grid of the capture (YAML from "
                          "plenocli calibrate, or the camera's RayCalibData XML)")
    side = intended or "left"
    if side not in ("left", "right"):
        raise ConfigError(f"with --mask-widths, --intended is 'left' or 'right', got {side!r}")
    data, meta = tiffio.read_image(inputs[0])
    framing = frame_grid(grid, meta, data.shape[1:], frames_path=inputs[0])
    try:
        check_mask_width(max(widths), framing.grid.pitch_px)
    except ValueError as err:
        raise OptionError(f"--mask-widths: {err}") from err
    from plenocli.depth.lenslet import sensor_grey  # with the sweep's numba kernels

    image = sensor_image(data, meta)
    frame = framing.crop(image)
    grey = sensor_grey(frame[np.newaxis], mosaic=bool(framing.cfa))
    whole = partial(beyond_grid, framing, image[np.newaxis], mosaic=bool(framing.cfa))
    if not check_fits(grey, framing.grid, grid, frames_path=inputs[0], whole=whole):
        warn_unchecked(grid)
    lens_grid, moved = centred_on(grey, framing.grid, grid)
    try:
        sweep = crosstalk_lib.refocus_mask_sweep(frame, lens_grid, widths, s=s, g=g,
                                                 intended=side, tile_px=tile)
    except ValueError as err:
        raise ConfigError(f"crosstalk --mask-widths: {err}") from err
    for row in sweep:  # as in every measurement: the open half is the brighter one everywhere
        _check_open_part(f"{inputs[0]} (mask width {row['mask_width']:g} px)", side,
                         max(row["r"], row["map_max"]))
    params = dict(intended=side, tile=tile, mask_widths=mask_widths, grid=grid, s=s, g=g)
    record = stage_record("crosstalk", params, {"inputs": inputs, "grid": grid})
    doc = {"sweep": sweep, "intended": side, "provenance": record,
           "grid_moved_px": None if moved is None else list(moved)}
    write_text(output, json.dumps(json_safe(doc), indent=1, allow_nan=False),
               protect=(inputs[0], grid))
    for row in sweep:
        log.info("crosstalk: m = %g px: r = %.2f %%", row["mask_width"], 100 * row["r"])


# ---------------------------------------------------------------------------------------------
# The whole mixing matrix M from one masked white per pupil part (``--mixing-out``).


def _check_open_part(path: str, name: str, r: float) -> None:
    """The open part of a masked white must be its brightest, over the whole frame and in
    every tile (``r`` the largest of them): r >= 1 makes M singular, and a tile where another
    view outshines it is a scene or the wrong view, not a white with that part open."""
    if not r < 1:
        raise InputError(f"{path}: the open part {name} is not brighter than the others "
                         f"everywhere (r up to {100 * r:.0f} %): not a white with only that part "
                         "open; check --intended and the mask")


def _processing(inputs: list[str]) -> list[str] | None:
    """The stages that made the masked whites (one list: they must be processed alike, as
    the capture whose views the mixing will unmix); None when they carry no record."""
    made = {tuple(processing_of(tiffio.read_meta(p))): p for p in inputs}
    if len(made) > 1:
        (one, first), (other, second) = list(made.items())[:2]
        raise InputError(f"{first} was made by {' > '.join(one) or 'no plenocli stage'} but "
                         f"{second} by {' > '.join(other) or 'no plenocli stage'}; process the "
                         "masked whites alike, as the capture")
    steps = next(iter(made))
    return list(steps) if steps else None


def _run_mixing(inputs: list[str], output: str, mixing_out: str, *, views: str | None,
                intended: str | None, tile: int, preview: str | None) -> None:
    """r of every masked white (as without --mixing-out) and the field M from all of them."""
    whites, labels = read_masked_whites(inputs, pupil_parts(inputs[0], views))
    first = whites[0]
    for label, white in zip(labels[1:], whites[1:], strict=True):
        if not white.same_kind(first):
            raise InputError(f"{label} does not match {inputs[0]} (views, colours, CFA or size); "
                             "give masked whites of one rig, processed the same way")
    made_by = _processing(inputs)
    names = first.names
    parts = pupil_views(tiffio.read_meta(inputs[0]).get("views") or [])
    if len(parts) > 1 and not set(parts) <= set(names):
        raise ConfigError(f"--views {views}: {inputs[0]} holds pupil parts "
                          f"{','.join(parts)}; a mixing must cover every part (each leaks "
                          "into the others): leave --views out, or name them all")
    if len(whites) != len(names):
        raise InputError(f"--mixing-out needs one masked white per pupil part: {len(names)} "
                         f"views ({','.join(names)}) but {len(whites)} inputs")
    specs = (intended or "auto").split(",")
    if len(specs) not in (1, len(whites)):
        raise ConfigError(f"--intended has {len(specs)} names for {len(whites)} masked whites; "
                          "give one name per masked white")
    captures, opened = [], []
    for k, (label, white) in enumerate(zip(labels, whites, strict=True)):
        idx = _intended_index(specs[k if len(specs) > 1 else 0], names, label)
        try:  # flux over every colour, as r has always been
            res = crosstalk_lib.crosstalk_ratio(white.data.sum(axis=1), intended=idx,
                                                tile_px=tile, cfa=white.cfa)
        except ValueError as err:
            raise InputError(f"{label}: {err}") from err
        _check_open_part(label, names[res["intended"]], res["r"])
        opened.append(res["intended"])
        captures.append(_capture_entry(label, names, res, tile, white.cfa))
    if sorted(opened) != list(range(len(names))):
        raise InputError("the masked whites must open each pupil part once; intended views were "
                         f"{','.join(names[j] for j in opened)}; pass --intended with one view "
                         "name per input")
    try:
        field = crosstalk_lib.measure_mixing_colours(
            [w.data for w in whites], intended=opened, views=names, colours=first.colours,
            tile_px=tile, colour_pattern=first.colour_pattern())
    except ValueError as err:
        raise InputError(f"crosstalk --mixing-out: {err}") from err
    from_m = crosstalk_lib.mixing_ratio(field)
    record = stage_record("crosstalk", dict(views=views, intended=intended, tile=tile),
                          {"inputs": inputs})
    history = [m for m in (tiffio.read_meta(p).get("provenance") for p in inputs) if m]
    doc = {"r": max(c["r"] for c in captures), "definition": "max flux on another view / flux "
           "on the intended view, over pixels finite in every view", "captures": captures,
           "mixing": {"file": mixing_out, "layout": first.layout, "tile_px": tile,
                      "definition": "view k records sum_j M_kj T_j; M_jj = 1; r = max over "
                      "k != j of M_kj / M_jj", **from_m}, "provenance": record}
    protect = tuple(inputs)
    write_mixing(mixing_out, field, layout=first.layout, cfa=first.cfa, made_by=made_by,
                 meta={"provenance": record, "history": history, "r_from_mixing": from_m},
                 protect=protect)
    write_text(output, json.dumps(json_safe(doc), indent=1, allow_nan=False), protect=protect)
    if preview:
        write_heat_map(preview, *_mixing_maps(field), protect=protect)
    log.info("crosstalk: mixing of %d views x %d colours on %d x %d tiles -> %s; r from M "
             "%.2f %% (mean), %.2f %% (max over tiles)", len(names), len(field.colours),
             field.nodes.shape[3], field.nodes.shape[4], shown(mixing_out),
             100 * from_m["r_mean"], 100 * from_m["r_max"])


def _mixing_maps(field) -> tuple[list[np.ndarray], list[str]]:
    """The off-diagonal M_kj of green (or the first colour) as maps with their titles."""
    c = field.colours.index("G") if "G" in field.colours else 0
    pairs = [(k, j) for k in range(field.n_views) for j in range(field.n_views) if k != j]
    return ([np.asarray(field.nodes[c, k, j], np.float64) for k, j in pairs],
            [f"M {field.views[k]}<-{field.views[j]} ({field.colours[c]})" for k, j in pairs])
