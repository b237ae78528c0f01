"""Lens-grid files: YAML (plenocli's own, human-readable) with provenance."""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np
import yaml

from plenocli.errors import InputError, not_a_file
from plenocli.io.atomic import write_text
from plenocli.io.yamlfile import DocumentError, load_yaml, read_text
from plenocli.model.lensgrid import FIELD_DEGREE, FIELD_MAX, MIN_PITCH_PX, LensGrid, fit_lattice
from plenocli.model.provenance import json_safe

# libyaml's emitter when PyYAML was built with it (10-50x faster; io/yamlfile reads)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def write_grid(path: str | os.PathLike, grid: LensGrid, provenance: dict, *,
               extra: dict | None = None, protect: tuple = ()) -> None:
    """Write ``grid`` as YAML; ``extra`` (e.g. residuals) is stored beside it. The record holds
    the sha256 of the grid as it reads back (:func:`vouched_by`)."""
    lens_grid = grid.to_dict(lens_rows=False)
    text = _dump({"lens_grid": lens_grid})
    if grid.centres_xy is not None:
        # tens of thousands of lenses: one flow-style row per line, formatted directly (a YAML
        # emitter takes seconds for this), still plain YAML for any reader
        text += "    rows:\n" + "".join(
            f"    - [{i}, {j}, {x:.5f}, {y:.5f}]\n"
            for (i, j), (x, y) in zip(np.asarray(grid.indices).tolist(),
                                      np.asarray(grid.centres_xy).tolist(), strict=True))
    record = {**provenance, GRID_SHA256: _grid_sha256(_fast_load(text) or load_yaml(text))}
    # numpy scalars from the calibration (a float64 pitch) as plain numbers: YAML-safe dump
    text += _dump(json_safe({**(extra or {}), "provenance": record}))
    write_text(path, text, protect=protect)


def _dump(doc: dict) -> str:
    return yaml.dump(doc, Dumper=_DUMPER, sort_keys=False, width=100)


# The lens table as write_grid lays it out: `    rows:` then one `    - [i, j, x, y]` per line.
# Only number forms that every YAML parser reads as these same numbers are accepted (no leading
# zeros: YAML 1.1 reads 012 as octal; no exponents: PyYAML reads 1e5 as a string); any other
# layout (hand-edited, re-indented, block style, CRLF) goes through the YAML parser.
_INT = r"-?(?:0|[1-9][0-9]*)"
_NUM = rf"(?:-?[0-9]+\.[0-9]+|{_INT})"
_ROW_LINES = re.compile(rf"(?:    - \[{_INT}, {_INT}, {_NUM}, {_NUM}\]\n)+")
_MORE_ITEMS = re.compile(r"(?:[ \t]*(?:#[^\n]*)?\n)*    -")
_ROWS_KEY = "\n    rows:\n"
_ROWS_SENTINEL = "plenocli-lens-rows"


def _split_rows(text: str) -> tuple[str, np.ndarray] | None:
    """(the document with the lens rows replaced by a placeholder, the rows as a (K, 4) float
    array), or None when the text does not hold write_grid's exact row layout. Parsing 85k rows
    with numpy takes ~0.1 s; a YAML parser needs ~5 s."""
    start = text.find(_ROWS_KEY)
    if start < 0 or text.find(_ROWS_KEY, start + 1) >= 0:
        return None
    first = start + len(_ROWS_KEY)
    block = _ROW_LINES.match(text, first)
    if block is None:
        return None
    end = block.end()
    if _MORE_ITEMS.match(text, end):   # the sequence goes on after a blank or comment line
        return None
    body = text[first:end].replace("    - [", "").replace("]\n", ",")
    table = np.array(body[:-1].split(","), dtype=float).reshape(-1, 4)
    return text[:start] + f"\n    rows: {_ROWS_SENTINEL}\n" + text[end:], table


def _fast_load(text: str) -> dict | None:
    """The YAML document with its lens rows parsed by numpy, or None (then parse it all)."""
    fast = _split_rows(text)
    if fast is None:
        return None
    try:
        doc = load_yaml(fast[0])
    except DocumentError:
        return None
    grid = doc.get("lens_grid") if isinstance(doc, dict) else None
    lenses = grid.get("lenses") if isinstance(grid, dict) else None
    if not isinstance(lenses, dict) or lenses.get("rows") != _ROWS_SENTINEL:
        return None   # the block was not lens_grid.lenses.rows after all
    lenses["rows"] = fast[1]
    return doc


def measured_on(path: str | os.PathLike) -> set[str]:
    """The sha256 of the images a YAML grid was calibrated on (its record's inputs), empty for
    an XML or a grid of no record: a grid measured on the very frames it is used on is checked
    by construction."""
    _, record = _record(path)
    if record.get("stage") != "calibrate":
        return set()
    return {str(i.get("sha256")) for i in record.get("inputs") or []
            if isinstance(i, dict) and i.get("sha256")}


# The record's checksum of the grid, and the stages whose grids are measured
# (calibrate, on a white or the frames) or true by construction (simulate, its own lattice).
GRID_SHA256 = "lens_grid_sha256"
VOUCHING_STAGES = ("calibrate", "simulate")
_TOP_KEY = re.compile(r"\n(?=[^\s#])")


def _grid_sha256(doc) -> str | None:
    """sha256 of the grid a YAML document describes, as the stages read it (its fields in
    canonical JSON, its lens rows as numbers), not of its text: a grid re-saved by another YAML
    writer (key order, quoting, flow or block rows) is the same grid. None for a document that
    holds none."""
    try:
        grid = LensGrid.from_dict(doc["lens_grid"])
    except (TypeError, KeyError, ValueError):
        return None
    digest = hashlib.sha256(json.dumps(grid.to_dict(lens_rows=False), sort_keys=True).encode())
    if grid.centres_xy is not None:
        digest.update(np.ascontiguousarray(grid.indices, "<i8").tobytes())
        digest.update(np.ascontiguousarray(grid.centres_xy, "<f8").tobytes())
    return digest.hexdigest()


def _text_sha256(text: str) -> str | None:
    """The checksum earlier records hold: of the lens_grid section's text as written (a grid
    re-saved unchanged by another writer fails it, hence ``_grid_sha256`` now)."""
    text = text.replace("\r\n", "\n")
    end = _TOP_KEY.search(text, 1) if text.startswith("lens_grid:") else None
    return None if end is None else hashlib.sha256(text[:end.start() + 1].encode()).hexdigest()


def vouched_by(path: str | os.PathLike) -> tuple[str | None, str]:
    """(the stage whose record vouches for the YAML grid at ``path``, None when none does; why
    not). A record vouches when a stage that measures grids or knows them (VOUCHING_STAGES)
    wrote it and the grid read is the one it wrote: its sha256 is the one the record holds. An
    XML, a hand-made grid, or one edited since (a pitch scaled by 1 %) has no record that
    vouches for it."""
    text, record = _record(path)
    if text is None or text.lstrip().startswith("<"):
        return None, "a Raytrix XML carries no plenocli record"
    stage = record.get("stage")
    if stage not in VOUCHING_STAGES:
        return None, ("its record names no stage that measured it (plenocli calibrate or "
                      "simulate)" if record else "it has no plenocli record")
    try:
        doc = _fast_load(text) or load_yaml(text)
    except DocumentError:
        doc = None
    if record.get(GRID_SHA256) not in {_grid_sha256(doc), _text_sha256(text)} - {None}:
        return None, f"its lens_grid was changed since `plenocli {stage}` wrote it"
    return stage, ""


def _record(path: str | os.PathLike) -> tuple[str | None, dict]:
    """(the text of a YAML grid, its provenance record or {}); (None, {}) for a file that is
    not one."""
    try:
        text = read_text(Path(path))
    except (OSError, InputError):
        return None, {}
    start = text.find("\nprovenance:")
    if start < 0:
        return text, {}
    try:
        record = load_yaml(text[start:]).get("provenance") or {}
    except (DocumentError, AttributeError):
        return text, {}
    return text, record if isinstance(record, dict) else {}


def read_grid(path: str | os.PathLike, *,
              image_shape: tuple[int, int] | None = None) -> LensGrid:
    """Read a lens grid from plenocli YAML or from a Raytrix RayCalibData XML.

    An XML gives its offset from the image centre, so ``image_shape`` (rows, cols) is required
    for it (see ``plenocli.io.raytrix``)."""
    p = Path(path)
    if not p.is_file():
        raise not_a_file(p)
    with open(p, "rb") as fh:
        head = fh.read(256).lstrip()
    if p.suffix.lower() == ".xml" or head.startswith(b"<"):
        from plenocli.io import raytrix

        calib = raytrix.read_calib(p)
        if image_shape is None:
            raise InputError(f"{p}: a Raytrix XML grid needs the image size (its offset is from "
                             "the image centre); pass the image it belongs to")
        try:
            return raytrix.grid_from_calib(calib, image_shape)
        except ValueError as err:
            raise InputError(f"{p}: not a usable lens grid ({err})") from err
    try:
        text = read_text(p)
        doc = _fast_load(text)
        if doc is None:
            doc = load_yaml(text)
    except DocumentError as err:
        reason = " ".join(str(err).split())
        raise InputError(f"{p}: not a YAML lens grid ({reason})") from err
    try:
        if not isinstance(doc, dict) or "lens_grid" not in doc:
            raise ValueError("no lens_grid")
        return LensGrid.from_dict(doc["lens_grid"])
    except ValueError as err:
        raise InputError(f"{p}: not a plenocli lens grid ({err}); make one with plenocli "
                         "calibrate") from err


def check_lens_rows(path, grid: LensGrid) -> None:
    """The listed lenses must be the lattice's: each centre nearer its own lattice place (i, j)
    than any other (within half a pitch; calibrated centres stray by tenths of a pixel), about
    the lattice as calibrate lists them (:func:`rows_misfit`), and inside the image the grid was
    calibrated on (a lens one pitch outside holds none of it)."""
    if grid.centres_xy is None or not len(grid.centres_xy):
        return
    indices, centres = np.asarray(grid.indices), np.asarray(grid.centres_xy, np.float64)
    stray = np.hypot(*(centres - grid.lattice_xy(indices[:, 0], indices[:, 1])).T)
    worst = int(np.argmax(stray))
    if stray[worst] >= grid.pitch_px / 2:
        i, j = indices[worst]
        raise InputError(f"{path}: lens ({i}, {j}) is listed at ({centres[worst][0]:.1f}, "
                         f"{centres[worst][1]:.1f}), {stray[worst]:.1f} px from its lattice "
                         f"place (pitch {grid.pitch_px:g} px): the lens rows do not belong to "
                         "this lattice; calibrate again")
    misfit = rows_misfit(grid)
    if misfit:
        raise InputError(f"{path}: {misfit}; the lens rows or the lattice fields (pitch_px, "
                         "angle_rad, offset_xy) were edited: calibrate again")
    if grid.image_shape is not None:
        rows, cols = grid.image_shape
        margin = grid.pitch_px
        outside = ((centres[:, 0] < -margin) | (centres[:, 0] > cols - 1 + margin)
                   | (centres[:, 1] < -margin) | (centres[:, 1] > rows - 1 + margin))
        if outside.any():
            k = int(np.argmax(outside))
            raise InputError(f"{path}: lens {tuple(int(v) for v in indices[k])} is listed at "
                             f"({centres[k][0]:.1f}, {centres[k][1]:.1f}), outside the "
                             f"{cols} x {rows} image the grid describes; calibrate again")


REFIT_PX = 0.05       # a lattice fitted to calibrated rows moves no lens farther than this
FIELD_FIT_PX = 0.01   # rows written as lattice + smooth field: their misfit to that polynomial


def rows_misfit(grid: LensGrid) -> str | None:
    """How the lens rows contradict the lattice fields, or None. Calibrate lists either the
    measured centres with the least-squares lattice through them (a lattice fitted to the rows
    is the file's lattice), or the lattice places moved by a smooth field (a polynomial of
    degree FIELD_DEGREE in the place, at most FIELD_MAX pitch). A uniform shift of the rows, a
    scaled pitch or a turned angle is neither."""
    indices, centres = np.asarray(grid.indices), np.asarray(grid.centres_xy, np.float64)
    places = grid.lattice_xy(indices[:, 0], indices[:, 1])
    pitch, angle, offset = fit_lattice(indices, centres, lattice=grid.lattice)
    refit = LensGrid(max(pitch, MIN_PITCH_PX), angle, offset, grid.lattice)
    moved = float(np.hypot(*(refit.lattice_xy(indices[:, 0], indices[:, 1]) - places).T).max())
    if moved <= REFIT_PX:
        return None
    shift = centres - places
    scaled = (places - places.mean(axis=0)) / np.maximum(np.ptp(places, axis=0) / 2, 1.0)
    design = np.stack([scaled[:, 0] ** a * scaled[:, 1] ** b for a in range(FIELD_DEGREE + 1)
                       for b in range(FIELD_DEGREE + 1 - a)], axis=1)
    smooth = design @ np.linalg.lstsq(design, shift, rcond=None)[0]
    off_field = float(np.hypot(*(shift - smooth).T).max())
    largest = float(np.hypot(*shift.T).max())
    if off_field <= FIELD_FIT_PX and largest <= FIELD_MAX * grid.pitch_px + FIELD_FIT_PX:
        return None
    return (f"the lattice its {len(centres)} lens rows fit (pitch {pitch:.4f} px, angle "
            f"{angle:.5f} rad) lies up to {moved:.2f} px from the lattice it lists (pitch "
            f"{grid.pitch_px:.4f} px, angle {grid.angle_rad:.5f} rad), and the rows are not "
            f"that lattice moved by a smooth field of at most {FIELD_MAX:g} pitch")
