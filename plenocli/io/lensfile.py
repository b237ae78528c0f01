"""Lens prescriptions as YAML (human-readable; see configs/lenses/paper_table2.yaml).

    name: my_lens
    image_distance_mm: 1.03669     # last vertex -> sensor (default: the last row's thickness)
    surfaces:                      # in the order light meets them
      - {stop: true, diameter: 3.09, thickness: 0.0}
      - {thickness: 1.82133, radius: 3.08301, glass: SK16, diameter: 3.53718, conic: 0.1747}

Units are millimetres. ``radius`` is signed (positive: centre of curvature towards the sensor),
``inf`` or omitted for a flat surface; ``glass`` is the medium after the surface (a catalogue
name, ``air``, or a constant index); ``conic`` is the standard conic constant K. Exactly one
surface is the aperture ``stop``; keys other than these are refused (a misspelt key would
otherwise be a silent default).
"""

from __future__ import annotations

import math
import os

from plenocli.errors import ConfigError
from plenocli.io.yamlfile import read_side_file
from plenocli.optics.glass import refractive_index
from plenocli.optics.lens import Lens, Surface

SURFACE_KEYS = {"thickness", "radius", "glass", "diameter", "conic", "stop"}
LENS_KEYS = {"name", "image_distance_mm", "surfaces", "notes"}


def _number(value, what: str) -> float:
    if value is None:
        return math.inf
    if isinstance(value, str) and value.strip().lower() in ("inf", "infinity", "flat"):
        return math.inf
    try:
        return float(value)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"{what}: {value!r} is not a number") from err


def lens_from_dict(doc: dict, *, source: str = "lens") -> Lens:
    """Build a :class:`Lens` from a parsed YAML document (errors name the row and key)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("surfaces"), list):
        raise ConfigError(f"{source}: a lens file needs a 'surfaces' list")
    unknown = set(doc) - LENS_KEYS
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
                          f"a lens file has {', '.join(sorted(LENS_KEYS))}")
    surfaces = [_surface(row, f"{source}: surface {k}")
                for k, row in enumerate(doc["surfaces"], 1)]
    image = doc.get("image_distance_mm")
    try:
        lens = Lens(tuple(surfaces), name=str(doc.get("name", source)),
                    image_distance_mm=(None if image is None
                                       else _number(image, "image_distance_mm")),
                    notes=str(doc.get("notes", "")))
    except ValueError as err:
        raise ConfigError(f"{source}: {err}") from err
    stops = [k for k, s in enumerate(surfaces, 1) if s.stop]
    if len(stops) != 1:
        raise ConfigError(f"{source}: " + (
            "no surface has 'stop: true'; mark the aperture stop (the f-number and pupils "
            "are the stop's)" if not stops else
            f"surfaces {', '.join(map(str, stops))} all have 'stop: true'; a lens has one "
            "aperture stop"))
    return lens


def _surface(row, where: str) -> Surface:
    """One row of the ``surfaces`` list (errors name the row and key)."""
    if not isinstance(row, dict):
        raise ConfigError(f"{where}: expected a mapping of {', '.join(sorted(SURFACE_KEYS))}")
    unknown = set(row) - SURFACE_KEYS
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
                          f"use {', '.join(sorted(SURFACE_KEYS))}")
    glass = row.get("glass", "air")
    try:
        refractive_index(glass)
    except ValueError as err:
        raise ConfigError(f"{where}: {err}") from err
    radius = _number(row.get("radius"), f"{where} radius")
    if radius == 0:
        raise ConfigError(f"{where}: radius 0 is no surface; give a signed radius in mm, or inf "
                          "(or omit it) for a flat surface")
    stop = row.get("stop", False)
    if not isinstance(stop, bool):
        raise ConfigError(f"{where}: stop {stop!r} must be true or false")
    return Surface(
        radius_mm=radius,
        thickness_mm=_number(row.get("thickness", 0.0), f"{where} thickness"),
        glass=glass,
        diameter_mm=_number(row.get("diameter"), f"{where} diameter"),
        conic=_number(row.get("conic", 0.0), f"{where} conic"),
        stop=stop,
    )


def read_lens(path: str | os.PathLike) -> Lens:
    """Read a lens prescription YAML file."""
    return lens_from_dict(read_side_file(path, "YAML lens prescription"), source=str(path))
