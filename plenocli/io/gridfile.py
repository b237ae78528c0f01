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


def read_grid(path: str | os.PathLike) -> LensGrid:
    """Read a lens grid from plenocli YAML."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
        return LensGrid.from_dict(doc["lens_grid"])
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise InputError(f"{p}: not a YAML lens grid ({err})") from err
    except (KeyError, TypeError, ValueError) as err:
        raise InputError(f"{p}: not a plenocli lens grid (missing or bad {err}); "
                         "make one with plenocli calibrate") from err
