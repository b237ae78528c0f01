"""Lens-grid files: YAML (plenocli's own, human-readable) with provenance."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from plenocli.errors import InputError
from plenocli.io.atomic import write_text
from plenocli.lensgrid import LensGrid

# libyaml's emitter and parser when PyYAML was built with it (10-50x faster)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def write_grid(path: str | os.PathLike, grid: LensGrid, provenance: dict, *,
               extra: dict | None = None, protect: tuple = ()) -> None:
    """Write ``grid`` as YAML; ``extra`` (e.g. residuals) is stored beside it."""
    lens_grid = grid.to_dict(lens_rows=False)
    text = _dump({"lens_grid": lens_grid})
    if grid.centres_xy is not None:
        # tens of thousands of lenses: one flow-style row per line, formatted directly (a YAML
        # emitter takes seconds for this), still plain YAML for any reader
        text += "    rows:\n" + "".join(
            f"    - [{i}, {j}, {x:.5f}, {y:.5f}]\n"
            for (i, j), (x, y) in zip(np.asarray(grid.indices).tolist(),
                                      np.asarray(grid.centres_xy).tolist(), strict=True))
    text += _dump({**(extra or {}), "provenance": provenance})
    write_text(path, text, protect=protect)


def _dump(doc: dict) -> str:
    return yaml.dump(doc, Dumper=_DUMPER, sort_keys=False, width=100)


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
        doc = yaml.load(p.read_text(encoding="utf-8"), Loader=_LOADER)
        return LensGrid.from_dict(doc["lens_grid"])
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise InputError(f"{p}: not a YAML lens grid ({err})") from err
    except (KeyError, TypeError, ValueError) as err:
        raise InputError(f"{p}: not a plenocli lens grid (missing or bad {err}); "
                         "make one with plenocli calibrate") from err
