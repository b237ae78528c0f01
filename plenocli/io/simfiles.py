"""The files of a simulated capture set: each :class:`~plenocli.synth.capture.SimFile` written
with the writer its format names (plain TIFF, plenocli TIFF, DNG, NumPy archive, lens grid,
RayCalibData XML), and the ground truth as ``truth.json``. Every write is atomic; the set lands
together or not at all."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from plenocli.io.atomic import outputs_together
from plenocli.model.provenance import json_safe

TRUTH_FILE = "truth.json"


def write_simulation(output: str | os.PathLike, files, truth: dict, record: dict) -> None:
    """Write ``files`` (SimFile) and ``truth.json`` into the folder ``output`` (created when
    missing); nothing of this run is left behind when a write fails."""
    out = Path(output)
    with outputs_together():
        for item in files:
            write_file(out / item.name, item, record)
        _write_truth(out / TRUTH_FILE, truth)


def _write_truth(path: Path, truth: dict) -> None:
    from plenocli.io.atomic import write_text

    write_text(path, json.dumps(json_safe(truth), indent=1, allow_nan=False) + "\n")


def write_file(path: Path, item, record: dict) -> None:
    """One SimFile with the writer its format names."""
    from plenocli.io import tiffio
    from plenocli.io.atomic import atomic_path

    if item.format == "tiff":
        import tifffile

        with atomic_path(path) as tmp:
            tifffile.imwrite(tmp, item.data, photometric=item.options["photometric"])
    elif item.format == "image":
        tiffio.write_image(path, item.data, tiffio.derived_meta(item.options["meta"], record))
    elif item.format == "dng":
        from plenocli.io.dng import write_dng

        write_dng(path, item.data, **item.options)
    elif item.format == "npz":
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **item.data)
    elif item.format == "grid":
        from plenocli.io.gridfile import write_grid

        write_grid(path, item.data, record)
    else:  # raytrix-xml
        from plenocli.io import raytrix

        raytrix.write_calib(path, raytrix.calib_from_grid(item.data))

