"""The project's image format: float32 (or integer) TIFF, one page per view, JSON metadata.

Any TIFF reader opens these files (one grey page per view). The first page's ImageDescription
holds a JSON object with everything later stages need:

``views``         names of the pages: ``["S", "A"]`` after decode, ``["A", "B", "S"]`` after bias
``cfa``           2 x 2 colour pattern at pixel (0, 0) of this array, e.g. ``"RGGB"``; null if none
``origin``        ``[row, col]`` of pixel (0, 0) in full-sensor coordinates (margins included), so
                  that grid coordinates stay true after crops
``black_level``   per view, per 2 x 2 pattern position (DN), as read from the raw
``white_level``   per view (DN): the clipping level of the raw
``active_area``   ``[top, left, bottom, right]`` of the light-sensitive area in this array
``masked_areas``  list of ``[top, left, bottom, right]`` over-scan (optical black) rectangles
``provenance``    this stage's record (plenocli version, stage, parameters, inputs with sha256)
``history``       the provenance records of the stages that made the inputs, oldest first
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import tifffile

from plenocli import __version__
from plenocli.errors import InputError
from plenocli.io.atomic import atomic_path

FORMAT_KEY = "plenocli_format"
FORMAT_VERSION = 1


def write_image(path: str | os.PathLike, views: np.ndarray, meta: dict, *,
                protect: tuple = ()) -> None:
    """Write ``views`` (rows, cols) or (views, rows, cols) with ``meta`` atomically."""
    data = np.asarray(views)
    if data.ndim == 2:
        data = data[np.newaxis]
    if data.ndim != 3:
        raise ValueError(f"views must be 2-D or 3-D, got shape {data.shape}")
    names = meta.get("views")
    if names is not None and len(names) != data.shape[0]:
        raise ValueError(f"{len(names)} view names for {data.shape[0]} views")
    description = json.dumps({FORMAT_KEY: FORMAT_VERSION, **meta}, allow_nan=True)
    with atomic_path(path, protect=protect) as tmp:
        with tifffile.TiffWriter(tmp) as tw:
            for k, page in enumerate(data):
                tw.write(np.ascontiguousarray(page), photometric="minisblack",
                         description=description if k == 0 else None, metadata=None,
                         software=f"plenocli {__version__}")


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, dict]:
    """Read a TIFF as (views, rows, cols) and its plenocli metadata ({} for a foreign TIFF)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    try:
        with tifffile.TiffFile(p) as tif:
            if not tif.pages:
                raise InputError(f"{p}: the TIFF holds no image")
            description = tif.pages[0].description
            series = tif.series[0] if len(tif.series) == 1 else None
            if series is not None and series.ndim == 3 and series.shape[0] == len(tif.pages):
                data = series.asarray()  # equal grey pages (plenocli's own): one read, no copy
            else:
                data = _stack_pages(p, [page.asarray() for page in tif.pages])
    except (tifffile.TiffFileError, ValueError, OSError, EOFError, IndexError) as err:
        raise InputError(f"{p}: not a readable TIFF image ({err}); "
                         "pass an image written by plenocli or a plain TIFF") from err
    meta: dict = {}
    if description:
        try:
            parsed = json.loads(description)
        except json.JSONDecodeError:
            parsed = None
        if isinstance(parsed, dict) and FORMAT_KEY in parsed:
            meta = {k: v for k, v in parsed.items() if k != FORMAT_KEY}
    return data, meta


def _stack_pages(path: Path, pages: list[np.ndarray]) -> np.ndarray:
    """Pages of a foreign TIFF as (views, rows, cols): interleaved samples (RGB) become views."""
    arrays = []
    for page in pages:
        if page.ndim == 3:
            arrays.extend(np.moveaxis(page, -1, 0))
        else:
            arrays.append(page)
    if len({a.shape for a in arrays}) != 1:
        raise InputError(f"{path}: the pages have different sizes; plenocli expects equal-sized "
                         "views")
    return np.stack(arrays)


def read_meta(path: str | os.PathLike) -> dict:
    """Only the plenocli metadata of a TIFF (cheap: no pixel data is read)."""
    try:
        with tifffile.TiffFile(path) as tif:
            description = tif.pages[0].description if tif.pages else ""
    except (tifffile.TiffFileError, ValueError, OSError):
        return {}
    try:
        parsed = json.loads(description) if description else {}
    except json.JSONDecodeError:
        return {}
    return {k: v for k, v in parsed.items() if k != FORMAT_KEY} if isinstance(parsed, dict) else {}


def derived_meta(source: dict, record: dict, **changes) -> dict:
    """Metadata for an output made from ``source``: history grows, ``changes`` override keys."""
    history = list(source.get("history", []))
    if source.get("provenance"):
        history.append(source["provenance"])
    meta = {k: v for k, v in source.items() if k not in ("provenance", "history")}
    meta.update(changes)
    meta["provenance"] = record
    meta["history"] = history
    return meta
