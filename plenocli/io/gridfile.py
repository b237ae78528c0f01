"""Lens-grid files: YAML (plenocli's own, human-readable) with provenance."""

from __future__ import annotations

import os
from pathlib import Path

import yaml

from plenocli.errors import InputError
from plenocli.io.atomic import write_text
from plenocli.lensgrid import LensGrid


def write_grid(path: str | os.PathLike, grid: LensGrid, provenance: dict, *,
               extra: dict | None = None, protect: tuple = ()) -> None:
    """Write ``grid`` as YAML; ``extra`` (e.g. residuals) is stored beside it."""
    doc = {"lens_grid": grid.to_dict(), **(extra or {}), "provenance": provenance}
    write_text(path, yaml.safe_dump(doc, sort_keys=False, width=100), protect=protect)


def read_grid(path: str | os.PathLike, *,
              image_shape: tuple[int, int] | None = None) -> LensGrid:
    """Read a lens grid from plenocli YAML or from a Raytrix RayCalibData XML.

    An XML gives its offset from the image centre, so ``image_shape`` (rows, cols) is required
    for it (see ``plenocli.io.raytrix``)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    with open(p, "rb") as fh:
        head = fh.read(256).lstrip()
    if p.suffix.lower() == ".xml" or head.startswith(b"<"):
        from plenocli.io import raytrix

        calib = raytrix.read_calib(p)
        if image_shape is None:
            raise InputError(f"{p}: a Raytrix XML grid needs the image size (its offset is from "
                             "the image centre); pass the image it belongs to")
        return raytrix.grid_from_calib(calib, image_shape)
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
        return LensGrid.from_dict(doc["lens_grid"])
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise InputError(f"{p}: not a YAML lens grid ({err})") from err
    except (KeyError, TypeError, ValueError) as err:
        raise InputError(f"{p}: not a plenocli lens grid (missing or bad {err}); "
                         "make one with plenocli calibrate") from err
