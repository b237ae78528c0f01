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
from plenocli.io.mixingfile import write_mixing
from plenocli.io.preview import write_heat_map
from plenocli.model.mixing import MixingField
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
    _check_once([names[k] for k in idx])
    return data[idx], [names[k] for k in idx]


def _check_once(names: list[str]) -> None:
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError(f"--views names view {twice[0]!r} twice; name each view once")


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
        g: float = 4.0, mixing_out: str | None = None) -> None:
    """Measure cross-talk on each input (one masked capture each), or sweep Raytrix mask widths;
    with ``mixing_out`` (one input per pupil part) also the mixing-matrix field M."""
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    if not inputs:
        raise InputError("no input given; pass one views TIFF per masked capture")
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
    """The cross-talk of one masked capture, as its entry in the report."""
    data, meta = tiffio.read_image(path)
    # e.g. --views A,B after bias: the sum view S must not count as "another view"
    data, names = select_views(data, meta, views)
    framing = active_area(meta, data.shape[1:])
    cfa = framing.cfa
    idx = _intended_index(intended, names, path)
    try:
        res = crosstalk_lib.crosstalk_ratio(framing.crop(data), intended=idx, tile_px=tile,
                                            cfa=cfa)
    except ValueError as err:
        raise InputError(f"{path}: {err}") from err
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


# ---------------------------------------------------------------------------------------------
# The whole mixing matrix M from one masked white per pupil part (``--mixing-out``).

CHANNELS = ("R", "G", "B")


def _channel_views(names: list[str]) -> tuple[list[str], list[str]] | None:
    """(views, channels) when the pages are VIEW.R, VIEW.G, VIEW.B for every view, else None."""
    groups: dict[str, list[str]] = {}
    for name in names:
        view, dot, channel = name.rpartition(".")
        if not dot or channel not in CHANNELS:
            return None
        groups.setdefault(view, []).append(channel)
    channels = next(iter(groups.values()))
    if len(groups) < 2 or any(c != channels for c in groups.values()):
        return None
    return list(groups), channels


def load_mixing_views(path: str, views: str | None) -> dict:
    """One views TIFF as ``data`` (V, C, rows, cols) float64 (active area only), ``names``,
    ``colours``, ``layout`` (cfa, channels or mono) and the 2 x 2 ``cfa`` of the area."""
    data, meta = tiffio.read_image(path)
    framing = active_area(meta, data.shape[1:])
    data, cfa = framing.crop(data), framing.cfa
    page_names = list(meta.get("views") or [str(k) for k in range(data.shape[0])])
    grouped = _channel_views(page_names)
    if grouped:
        names, channels = grouped
        if views:
            wanted = [v.strip() for v in views.split(",") if v.strip()]
            missing = [v for v in wanted if v not in names]
            _check_once(wanted)
            if missing:
                raise InputError(f"{path}: view {missing[0]!r} is not in the input (views: "
                                 f"{','.join(names)}); pass --views with names from that list")
            names = wanted
        index = {n: k for k, n in enumerate(page_names)}
        stack = np.stack([[data[index[f"{v}.{c}"]] for c in channels] for v in names])
        return {"data": stack.astype(np.float64), "names": names, "colours": channels,
                "layout": "channels", "cfa": None}
    chosen, names = select_views(data, meta, views)
    layout = "cfa" if cfa else "mono"
    colours = sorted(set(cfa.upper()), key="RGB".index) if cfa else ["L"]
    return {"data": chosen[:, None].astype(np.float64), "names": names, "colours": colours,
            "layout": layout, "cfa": cfa}


def _check_open_part(path: str, name: str, r: float) -> None:
    """The open part of a masked white must be its brightest: r >= 1 makes M singular."""
    if not r < 1:
        raise InputError(f"{path}: the open part {name} is not brighter than the others "
                         f"(r = {100 * r:.0f} %): not a white with only that part open; check "
                         "--intended and the mask")


def _run_mixing(inputs: list[str], output: str, mixing_out: str, *, views: str | None,
                intended: str | None, tile: int, preview: str | None) -> None:
    """r of every masked white (as without --mixing-out) and the field M from all of them."""
    loaded, labels = _load_masked_whites(inputs, views)
    first = loaded[0]
    for path, cap in zip(labels[1:], loaded[1:], strict=False):
        if (cap["names"], cap["colours"], cap["layout"], cap["cfa"], cap["data"].shape) != (
                first["names"], first["colours"], first["layout"], first["cfa"],
                first["data"].shape):
            raise InputError(f"{path} does not match {inputs[0]} (views, colours, CFA or size); "
                             "give masked whites of one rig, processed the same way")
    names = first["names"]
    if len(loaded) != len(names):
        raise InputError(f"--mixing-out needs one masked white per pupil part: {len(names)} "
                         f"views ({','.join(names)}) but {len(loaded)} inputs")
    specs = (intended or "auto").split(",")
    if len(specs) not in (1, len(loaded)):
        raise ConfigError(f"--intended has {len(specs)} names for {len(loaded)} masked whites; "
                          "give one name per masked white")
    captures, opened = [], []
    for k, (path, cap) in enumerate(zip(labels, loaded, strict=True)):
        luminance = cap["data"].sum(axis=1)  # flux over every colour, as r has always been
        idx = _intended_index(specs[k if len(specs) > 1 else 0], names, path)
        pattern = _cfa_pattern(cap)
        try:
            res = crosstalk_lib.crosstalk_ratio(luminance, intended=idx, tile_px=tile,
                                                cfa=cap["cfa"])
        except ValueError as err:
            raise InputError(f"{path}: {err}") from err
        _check_open_part(path, names[res["intended"]], res["r"])
        opened.append(res["intended"])
        captures.append({
            "input": path, "views": names, "intended": names[res["intended"]], "r": res["r"],
            "r_per_view": {names[j]: v for j, v in res["r_per_view"].items()},
            "map_min": res["map_min"], "map_max": res["map_max"], "tile_px": tile,
            "valid_fraction": res["valid_fraction"], "cfa": cap["cfa"],
            "per_colour": {c: {"r": d["r"], "map": d["map"]} for c, d in
                           res["per_colour"].items()}, "map": res["map"]})
    if sorted(opened) != list(range(len(names))):
        raise InputError("the masked whites must open each pupil part once; intended views were "
                         f"{','.join(names[j] for j in opened)}; pass --intended with one view "
                         "name per input")
    per_colour = []
    for c in range(len(first["colours"]) if first["layout"] == "channels" else 1):
        plane = [cap["data"][:, c] for cap in loaded]
        per_colour.append(crosstalk_lib.measure_mixing(
            plane, intended=opened, views=names, tile_px=tile, colour_pattern=pattern,
            colours=first["colours"] if first["layout"] != "channels" else
            [first["colours"][c]]))
    field = per_colour[0] if len(per_colour) == 1 else MixingField(
        np.concatenate([f.nodes for f in per_colour]), per_colour[0].node_rows,
        per_colour[0].node_cols, per_colour[0].shape, tuple(names), tuple(first["colours"]))
    from_m = crosstalk_lib.mixing_ratio(field)
    params = dict(views=views, intended=intended, tile=tile)
    record = stage_record("crosstalk", params, {"inputs": inputs})
    history = [m for m in (tiffio.read_meta(p).get("provenance") for p in inputs) if m]
    doc = {"r": max(c["r"] for c in captures), "definition": "max flux on another view / flux "
           "on the intended view, over pixels finite in every view", "captures": captures,
           "mixing": {"file": mixing_out, "layout": first["layout"], "tile_px": tile,
                      "definition": "view k records sum_j M_kj T_j; M_jj = 1; r = max over "
                      "k != j of M_kj / M_jj", **from_m}, "provenance": record}
    protect = tuple(inputs)
    write_mixing(mixing_out, field, layout=first["layout"], cfa=first["cfa"],
                 meta={"provenance": record, "history": history, "r_from_mixing": from_m},
                 protect=protect)
    write_text(output, json.dumps(json_safe(doc), indent=1, allow_nan=False), protect=protect)
    if preview:
        maps, titles = [], []
        shown_colour = field.colours.index("G") if "G" in field.colours else 0
        for k in range(len(names)):
            for j in range(len(names)):
                if k != j:
                    maps.append(np.asarray(field.nodes[shown_colour, k, j], np.float64))
                    titles.append(f"M {names[k]}<-{names[j]} ({field.colours[shown_colour]})")
        write_heat_map(preview, maps, titles, protect=protect)
    log.info("crosstalk: mixing of %d views x %d colours on %d x %d tiles -> %s; r from M "
             "%.2f %% (mean), %.2f %% (max over tiles)", len(names), len(field.colours),
             field.nodes.shape[3], field.nodes.shape[4], shown(mixing_out),
             100 * from_m["r_mean"], 100 * from_m["r_max"])


def _load_masked_whites(inputs: list[str], views: str | None) -> tuple[list[dict], list[str]]:
    """The masked whites and a label for each. Files of one view each (refocused left/right
    images) come V to a masked white, in the order --views names them."""
    single = all(len(tiffio.read_meta(p).get("views") or [None, None]) == 1 for p in inputs)
    if not single:
        return [load_mixing_views(p, views) for p in inputs], inputs
    names = [v.strip() for v in (views or "").split(",") if v.strip()]
    if len(names) < 2 or len(inputs) != len(names) ** 2:
        raise InputError(f"each input holds one view: name the views with --views (e.g. "
                         f"left,right) and give that many files per masked white, in that order "
                         f"({len(inputs)} files given)")
    loaded, labels = [], []
    for k in range(0, len(inputs), len(names)):
        group = inputs[k:k + len(names)]
        parts = [load_mixing_views(p, None) for p in group]
        cap = dict(parts[0])
        if len({p["data"].shape for p in parts}) != 1:
            raise InputError(f"{', '.join(group)}: the views of one masked white differ in size")
        cap["data"] = np.concatenate([p["data"] for p in parts])
        cap["names"] = names
        loaded.append(cap)
        labels.append("+".join(group))
    return loaded, labels


def _cfa_pattern(cap: dict) -> np.ndarray | None:
    """2 x 2 indices into the capture's colours of its Bayer pattern (None: not a mosaic)."""
    if cap["layout"] != "cfa":
        return None
    return np.array([cap["colours"].index(ch) for ch in cap["cfa"].upper()]).reshape(2, 2)
