"""What a file holds, for ``plenocli info``: raws, plenocli TIFFs, lens grids, configs, XML.

:func:`describe` returns a JSON-ready dict (``kind`` says which reader answered);
:func:`format_info` turns it into a few human-readable lines.
"""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from plenocli.errors import InputError, library_words, not_a_file
from plenocli.io import raw as raw_io
from plenocli.io.photo import photo_record
from plenocli.io.preview import is_preview
from plenocli.io.tiffio import open_tiff, read_meta
from plenocli.io.yamlfile import DocumentError, read_json, read_yaml
from plenocli.model import orientation
from plenocli.model.lensgrid import LensGrid
from plenocli.model.provenance import json_safe

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png")
IMAGE_KEYS = ("views", "cfa", "origin", "black_level", "white_level", "active_area",
              "masked_areas", "orientation")
TIFF_MODEL_TAGS = (50708, 272)  # DNG UniqueCameraModel, TIFF Model


def describe(path: str | os.PathLike, *, record: dict | None = None) -> dict[str, Any]:
    """A summary of ``path``: kind, sizes, levels, geometry and provenance (strict JSON values:
    an infinite or NaN level, as files of older versions hold, is None). ``record``: the
    record plenocli keeps beside an output it wrote (:mod:`plenocli.pipeline.records`), shown
    for a file that carries no provenance of its own (a preview, a report, a grid)."""
    info = _describe(path)
    if record is not None and not info.get("provenance"):
        info["record"] = {key: record.get(key) for key in ("version", "stage", "role",
                                                           "parameters")}
        info["record"]["inputs"] = {role: [str(state[-1]) for state in states]
                                    for role, states in record.get("inputs", {}).items()}
    return json_safe(info)


def _describe(path: str | os.PathLike) -> dict[str, Any]:
    p = Path(path)
    if not p.is_file():
        raise not_a_file(p)
    head = {"file": str(p), "bytes": p.stat().st_size}
    suffix = p.suffix.lower()
    if suffix in (".yaml", ".yml"):
        return {**head, **_describe_yaml(p)}
    if suffix == ".xml":
        return {**head, **_describe_xml(p)}
    if suffix == ".json":
        return {**head, **_describe_json(p)}
    if suffix in PHOTO_SUFFIXES and photo_record(p):
        return {**head, **_describe_photo(p)}
    if suffix == ".png" and is_preview(p):
        return {**head, **_describe_photo(p), "kind": "preview"}
    kind = raw_io.sniff(p)  # a damaged or truncated TIFF is refused here, not described
    if kind in ("canon-dp", "dng"):
        return {**head, **_describe_raw(p)}
    if kind == "image":
        meta = read_meta(p) if suffix in (".tif", ".tiff") else {}
        if not meta and photo_record(p):
            return {**head, **_describe_photo(p)}
        return {**head, **(_describe_plenocli_tiff(p, meta) if meta else _describe_image(p))}
    raise InputError(f"{p}: plenocli does not know this kind of file (expected a raw, a TIFF, "
                     "a lens grid or config YAML, a Raytrix XML or a JSON report)")


def _describe_raw(p: Path) -> dict:
    frames, meta = raw_io.decode(p)
    model = None
    if meta["camera"] == "dng":
        with open_tiff(p) as tif:
            tags = tif.pages[0].tags
            model = next((str(tags[c].value) for c in TIFF_MODEL_TAGS if c in tags), None)
    top, left, bottom, right = meta["active_area"]
    stats = []
    for name, frame in zip(meta["views"], frames, strict=True):
        active = frame[top:bottom, left:right]
        stats.append({"view": name, "min": int(active.min()), "max": int(active.max()),
                      "mean": round(float(active.mean()), 2)})
    return {"kind": "raw", "format": meta["camera"], "camera_model": model,
            "frames": int(frames.shape[0]), "rows": int(frames.shape[1]),
            "cols": int(frames.shape[2]), "dtype": str(frames.dtype),
            **{k: meta.get(k) for k in IMAGE_KEYS}, "active_stats": stats}


def _describe_plenocli_tiff(p: Path, meta: dict) -> dict:
    with open_tiff(p) as tif:
        page = tif.pages[0]
        dtype, count = str(page.dtype), len(tif.pages)
        rows, cols = page.imagelength, page.imagewidth
        if page.samplesperpixel > 1:  # samples are views (as the reader takes them)
            count *= page.samplesperpixel
    extra = {k: v for k, v in meta.items()
             if k not in (*IMAGE_KEYS, "provenance", "history")}
    return {"kind": "plenocli-tiff", "pages": count, "rows": int(rows),
            "cols": int(cols), "dtype": dtype, **{k: meta.get(k) for k in IMAGE_KEYS},
            "provenance": meta.get("provenance"), "history": meta.get("history", []),
            "extra": extra}


def _describe_photo(p: Path) -> dict:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(p) as image:
            cols, rows = image.size
            mode, fmt = image.mode, image.format
    except (OSError, UnidentifiedImageError) as err:
        raise InputError(f"{p}: not a readable photograph ({library_words(err)})") from err
    doc = photo_record(p) or {}
    return {"kind": "photo", "format": fmt, "rows": rows, "cols": cols, "mode": mode,
            "provenance": doc.get("plenocli"), "history": doc.get("history", [])}


def _describe_image(p: Path) -> dict:
    frames, meta = raw_io.decode(p)
    return {"kind": "image", "frames": int(frames.shape[0]), "rows": int(frames.shape[1]),
            "cols": int(frames.shape[2]), "dtype": str(frames.dtype), "views": meta["views"],
            "min": float(np.min(frames)), "max": float(np.max(frames))}


def _describe_yaml(p: Path) -> dict:
    try:
        doc = read_yaml(p)
    except DocumentError as err:
        raise InputError(f"{p}: not valid YAML ({err})") from err
    if isinstance(doc, dict) and isinstance(doc.get("lens_grid"), dict):
        try:  # a grid no stage would accept is said so, not described
            LensGrid.from_dict(doc["lens_grid"])
        except ValueError as err:
            raise InputError(f"{p}: not a usable lens grid ({err})") from err
        grid = dict(doc["lens_grid"])
        lenses = grid.pop("lenses", None)
        others = {k: v for k, v in doc.items() if k not in ("lens_grid", "provenance")}
        return {"kind": "lens-grid", **grid,
                "lens_count": lenses.get("count") if isinstance(lenses, dict) else None,
                "extra": others, "provenance": doc.get("provenance")}
    if isinstance(doc, dict) and isinstance(doc.get("steps"), dict):
        # what run reads: a description that is not text, or a step that is not a mapping,
        # is said in "run refuses it" (the command's check), not described
        steps = {name: (body or {}).get("stage", name) for name, body in doc["steps"].items()
                 if isinstance(name, str) and isinstance(body, (dict, type(None)))}
        description = doc.get("description")
        return {"kind": "pipeline-config",
                "description": description if isinstance(description, str) else None,
                "out": doc.get("out"), "steps": steps}
    return {"kind": "yaml", "keys": list(doc) if isinstance(doc, dict) else None}


def _describe_xml(p: Path) -> dict:
    # RayCalibData gets the Raytrix reader (validated fields, lattice in plain words); any other
    # XML a generic view of its root tag and top-level fields.
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as err:
        raise InputError(f"{p}: not well-formed XML ({err})") from err
    if root.tag == "RayCalibData":
        from plenocli.io.raytrix import read_calib

        calib = read_calib(p)
        return {"kind": "raytrix-calibration", "root": root.tag, "calibration": calib}
    return {"kind": "xml", "root": root.tag, "attributes": dict(root.attrib),
            "fields": _xml_children(root)}


def _xml_value(elem: ET.Element) -> Any:
    children = list(elem)
    if not children:
        text = (elem.text or "").strip()
        try:
            value: Any = float(text) if text else None
        except ValueError:
            value = text
        if elem.attrib:
            return {"value": value, **elem.attrib}
        return value
    return {**elem.attrib, **_xml_children(elem)}


def _xml_children(elem: ET.Element) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for child in elem:
        value = _xml_value(child)
        if child.tag in out:  # repeated tags become a list
            if not isinstance(out[child.tag], list):
                out[child.tag] = [out[child.tag]]
            out[child.tag].append(value)
        else:
            out[child.tag] = value
    return out


def _describe_json(p: Path) -> dict:
    try:
        doc = read_json(p)
    except DocumentError as err:
        raise InputError(f"{p}: not valid JSON ({err})") from err
    if not isinstance(doc, dict):
        return {"kind": "json", "keys": None}
    return {"kind": "json", "keys": [k for k in doc if k != "provenance"],
            "provenance": doc.get("provenance")}


# ------------------------------------------------------------------------------- text output

def format_info(info: dict) -> str:
    """Human-readable lines for a :func:`describe` result."""
    lines = [f"{info['file']}: {_title(info)} ({_size(info['bytes'])})"]
    fields = _KIND_FIELDS.get(info["kind"], _other_fields)(info)
    record = info.get("provenance")
    if record:
        lines += _field_lines(fields)
        lines.append(f"  made by        plenocli {record.get('version')} {record.get('stage')} "
                     f"on {record.get('created')}")
        fields = [("parameters", record.get("parameters"))]
        fields += [(f"input {item.get('role')}",
                    f"{item.get('path')} (sha256 {str(item.get('sha256'))[:12]}...)")
                   for item in record.get("inputs", [])]
    made = info.get("record")
    if made:  # the record beside the file: no time or paths, the digests of its inputs
        lines += _field_lines(fields)
        lines.append(f"  made by        plenocli {made.get('version')} {made.get('stage')} "
                     f"(its {made.get('role')}, says the record beside the file)")
        fields = [("parameters", made.get("parameters"))]
        fields += [(f"input {role}", ", ".join(f"sha256 {d[:12]}..." for d in digests))
                   for role, digests in (made.get("inputs") or {}).items()]
    fields += [(f"history {k}", f"{past.get('stage')} {_short(past.get('parameters'))} "
                                f"on {past.get('created')}")
               for k, past in enumerate(info.get("history") or [], 1)]
    refused = [f"  run refuses it: {info['refused']}"] if info.get("refused") else []
    return "\n".join(lines + _field_lines(fields) + refused)


def _field_lines(fields: list[tuple[str, object]]) -> list[str]:
    """One indented ``label value`` line per field that has a value."""
    return [f"  {label:<14} {_short(value)}" for label, value in fields
            if value is not None and value != [] and value != {}]


def _extra_fields(info: dict) -> list[tuple[str, object]]:
    return [(key.replace("_", " "), value) for key, value in (info.get("extra") or {}).items()]


def _image_fields(info: dict) -> list[tuple[str, object]]:
    count = info.get("frames", info.get("pages"))
    fields = [("size", f"{count} x {info['rows']} x {info['cols']} {info['dtype']} "
                       "(views x rows x cols)"),
              ("camera", info.get("camera_model"))]
    fields += [(key.replace("_", " "), info.get(key)) for key in IMAGE_KEYS]
    if info.get("orientation") is not None:  # what the number means (checked where read)
        fields[-1] = ("orientation", orientation.said(info["orientation"]))
    if info["kind"] == "image":
        fields.append(("values", f"min {info['min']:g}, max {info['max']:g}"))
    fields += [(f"view {s['view']}", f"active area min {s['min']}, max {s['max']}, "
                                     f"mean {s['mean']} DN")
               for s in info.get("active_stats", [])]
    return fields + _extra_fields(info)


def _grid_fields(info: dict) -> list[tuple[str, object]]:
    keys = ("lattice", "pitch_px", "angle_deg", "offset_xy", "image_shape", "sensor_origin",
            "lens_count")
    return [(key.replace("_", " "), info.get(key)) for key in keys] + _extra_fields(info)


def _config_fields(info: dict) -> list[tuple[str, object]]:
    return ([("description", (info.get("description") or "").strip() or None),
             ("out", info.get("out"))]
            + [(f"step {name}", f"stage {stage}") for name, stage in info["steps"].items()
               if isinstance(stage, str)])


def _raytrix_fields(info: dict) -> list[tuple[str, object]]:
    calib = info["calibration"]
    keys = ("lens_base_x", "lens_base_y", "lens_border", "tcp", "sub_grid_base", "distortion",
            "lens_types", "k_matrix")
    return ([("lens pitch", f"{calib['diameter']:g} px (diameter)"),
             ("rotation", f"{calib['rotation']:g} rad"),
             ("offset", f"{_short(calib['offset'])} px from the image centre, y up")]
            + [(key.replace("_", " "), calib.get(key)) for key in keys])


def _xml_fields(info: dict) -> list[tuple[str, object]]:
    attributes = _short(info["attributes"]) if info["attributes"] else ""
    return [("root", f"<{info['root']}> {attributes}"), *info["fields"].items()]


def _other_fields(info: dict) -> list[tuple[str, object]]:
    return [("keys", info.get("keys"))]


def _photo_fields(info: dict) -> list[tuple[str, object]]:
    return [("size", f"{info['cols']} x {info['rows']} {info['mode']}")]


_KIND_FIELDS = {"raw": _image_fields, "plenocli-tiff": _image_fields, "image": _image_fields,
                "lens-grid": _grid_fields, "pipeline-config": _config_fields,
                "raytrix-calibration": _raytrix_fields, "xml": _xml_fields,
                "photo": _photo_fields, "preview": _photo_fields}


def _title(info: dict) -> str:
    kind = info["kind"]
    if kind == "raw":
        return f"raw capture ({info['format']})"
    if kind == "plenocli-tiff":
        stage = (info.get("provenance") or {}).get("stage")
        return "plenocli image" + (f" from stage {stage}" if stage else "")
    if kind == "photo":
        return f"photograph ({info['format']})"
    if kind == "preview":
        stage = (info.get("record") or {}).get("stage")
        return (f"plenocli preview ({info['format']}, display-stretched 8-bit levels, not "
                "sensor data" + (f"; of a {stage} output" if stage else "") + ")")
    return {"image": "sensor image", "lens-grid": "lens grid", "xml": "XML document",
            "pipeline-config": "pipeline config", "json": "JSON document",
            "yaml": "YAML document"}.get(kind, kind)


def _size(n: int) -> str:
    for unit in ("bytes", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return str(n)


def _short(value, limit: int = 88) -> str:
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= limit else text[: limit - 3] + "..."
