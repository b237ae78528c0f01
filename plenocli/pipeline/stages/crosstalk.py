"""Stage ``crosstalk``: masked-pupil white captures (views TIFFs) -> cross-talk JSON + heat map."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from plenocli import crosstalk as crosstalk_lib
from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.io.atomic import write_text
from plenocli.io.framing import active_area, frame_grid, sensor_image
from plenocli.io.preview import write_heat_map
from plenocli.model.provenance import json_safe, stage_record
from plenocli.progress import log, shown


def select_views(data: np.ndarray, meta: dict, views: str | None) -> tuple[np.ndarray, list[str]]:
    """Pages of ``data`` named in ``views`` ("A,B"; names from the metadata, or page numbers)."""
    names = list(meta.get("views") or [str(k) for k in range(data.shape[0])])
    if not views:
        return data, names
    wanted = [v.strip() for v in views.split(",") if v.strip()]
    idx = []
    for name in wanted:
        if name in names:
            idx.append(names.index(name))
        elif name.isdigit() and int(name) < data.shape[0]:
            idx.append(int(name))
        else:
            raise InputError(f"view {name!r} is not in the input (views: {','.join(names)}); "
                             "pass --views with names from that list")
    return data[idx], [names[k] for k in idx]


def _intended_index(spec: str | None, names: list[str], path: str) -> int | None:
    if spec is None or spec == "auto":
        return None
    if spec in names:
        return names.index(spec)
    if spec.isdigit() and int(spec) < len(names):
        return int(spec)
    raise InputError(f"{path}: intended view {spec!r} is not one of {','.join(names)}; pass "
                     "--intended with a view name (or 'auto' for the brightest view)")


def run(inputs: tuple[str, ...] | list[str], output: str, *, views: str | None = None,
        intended: str | None = None, tile: int = 64, preview: str | None = None,
        mask_widths: str | None = None, grid: str | None = None, s: float = 0.2,
        g: float = 4.0) -> None:
    """Measure cross-talk on each input (one masked capture each), or sweep Raytrix mask widths."""
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    if not inputs:
        raise InputError("no input given; pass one views TIFF per masked capture")
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
    """The cross-talk of one masked capture, as its entry in the report."""
    data, meta = tiffio.read_image(path)
    # e.g. --views A,B after bias: the sum view S must not count as "another view"
    data, names = select_views(data, meta, views)
    framing = active_area(meta, data.shape[1:])
    cfa = framing.cfa
    idx = _intended_index(intended, names, path)
    res = crosstalk_lib.crosstalk_ratio(framing.crop(data), intended=idx, tile_px=tile, cfa=cfa)
    return {
        "input": path, "views": names, "intended": names[res["intended"]],
        "r": res["r"], "r_per_view": {names[j]: v for j, v in res["r_per_view"].items()},
        "map_min": res["map_min"], "map_max": res["map_max"], "tile_px": tile,
        "valid_fraction": res["valid_fraction"], "cfa": cfa,
        "per_colour": {c: {"r": d["r"], "map": d["map"]} for c, d in res["per_colour"].items()},
        "map": res["map"],
    }


def _run_sweep(inputs: list[str], output: str, *, intended: str | None, tile: int,
               mask_widths: str, grid: str | None, s: float, g: float) -> None:
    """Raytrix: refocus left/right views of a half-masked white capture for each mask width."""
    try:
        widths = [float(w) for w in mask_widths.split(",") if w.strip()]
    except ValueError as err:
        raise ConfigError(f"--mask-widths {mask_widths!r} is not a comma-separated list of "
                          "numbers (e.g. 0,1,2,3)") from err
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
    frame = framing.crop(sensor_image(data, meta))
    try:
        sweep = crosstalk_lib.refocus_mask_sweep(frame, framing.grid, widths, s=s, g=g,
                                                 intended=side, tile_px=tile)
    except ValueError as err:
        raise ConfigError(f"crosstalk --mask-widths: {err}") from err
    params = dict(intended=side, tile=tile, mask_widths=mask_widths, grid=grid, s=s, g=g)
    record = stage_record("crosstalk", params, {"inputs": inputs, "grid": grid})
    doc = {"sweep": sweep, "intended": side, "provenance": record}
    write_text(output, json.dumps(json_safe(doc), indent=1, allow_nan=False),
               protect=(inputs[0], grid))
    for row in sweep:
        log.info("crosstalk: m = %g px: r = %.2f %%", row["mask_width"], 100 * row["r"])
