"""The project's image format: float32 (or integer) TIFF, one page per view, JSON metadata.

Any TIFF reader opens these files (one grey page per view). The first page's ImageDescription
holds a JSON object with everything later stages need:

``views``         names of the pages: ``["S", "A"]`` after decode, ``["A", "B", "S"]`` after bias
``cfa``           2 x 2 colour pattern at pixel (0, 0) of this array, e.g. ``"RGGB"``; null if none
``origin``        ``[row, col]`` of pixel (0, 0) in full-sensor coordinates (margins included), so
                  that grid coordinates stay true after crops
``black_level``   per view, per 2 x 2 pattern position (DN), as read from the raw
``view_colours``  per view: its Bayer pattern, or the one colour it holds (R, G or B: the SAIs
                  of a per-pixel Bayer sensor), or null
``white_level``   per view (DN): the clipping level of the raw; null for a float image decoded
                  without --white (none known: nothing is taken as clipped)
``active_area``   ``[top, left, bottom, right]`` of the light-sensitive area in this array
``masked_areas``  list of ``[top, left, bottom, right]`` over-scan (optical black) rectangles
``provenance``    this stage's record (plenocli version, stage, parameters, inputs with sha256)
``history``       the provenance records of the stages that made the inputs, oldest first
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import tifffile

from plenocli import __version__
from plenocli.errors import InputError, library_words, not_a_file, numbers, plain_words
from plenocli.io.atomic import atomic_path
from plenocli.io.tiffsegments import (  # noqa: F401 (the readers' checks, used via tiffio)
    MAX_PAGE_PIXELS,
    check_light_levels,
    check_page,
    check_real_dtype,
    check_segments,
    page_levels,
    sample_tops,
)
from plenocli.io.yamlfile import DocumentError, load_json
from plenocli.model import orientation
from plenocli.model.cfa import is_bayer
from plenocli.model.provenance import json_safe
from plenocli.progress import log

FORMAT_KEY = "plenocli_format"
FORMAT_VERSION = 1
# What reading a damaged file raises, from tifffile or the codec of a compressed page (zlib,
# imagecodecs raise their own errors, RuntimeError subclasses); all of them mean "bad input".
# struct.error: tifffile unpacks a header or an IFD count past the end of a cut file
READ_ERRORS = (tifffile.TiffFileError, ValueError, OSError, EOFError, IndexError, KeyError,
               RuntimeError, zlib.error, struct.error)


def read_error(path, err: Exception, fallback: str) -> InputError:
    """One line for a TIFF that tifffile could not read: a missing codec says so (the file is
    fine: another program compressed it); anything else gets ``fallback``."""
    match = re.search(r"COMPRESSION\.(\w+).*requires the 'imagecodecs' package", str(err))
    if match:
        return InputError(f"{path}: compressed with {match.group(1)}, which this installation "
                          "cannot decode; pip install imagecodecs, or save the TIFF "
                          "uncompressed")
    return InputError(fallback)


def write_image(path: str | os.PathLike, views: np.ndarray, meta: dict, *,
                protect: tuple = (), seal: bool = False) -> None:
    """Write ``views`` (rows, cols) or (views, rows, cols) with ``meta`` atomically; ``seal``
    records the pixels' checksum (a side file a later stage trusts: :func:`check_seal`)."""
    data = np.asarray(views)
    if data.ndim == 2:
        data = data[np.newaxis]
    if data.ndim != 3:
        raise ValueError(f"views must be 2-D or 3-D, got shape {data.shape}")
    meta = {k: v for k, v in meta.items() if k != SEAL_KEY}
    if seal:
        meta[SEAL_KEY] = pixels_digest(data, meta)
    check_result(path, data, meta)
    description = describe(meta)
    with atomic_path(path, protect=protect) as tmp:
        with tifffile.TiffWriter(tmp) as tw:
            for k, page in enumerate(data):
                tw.write(np.ascontiguousarray(page), photometric="minisblack",
                         description=description if k == 0 else None, metadata=None,
                         software=f"plenocli {__version__}")


def describe(meta: dict) -> str:
    """The first page's ImageDescription: the format's key and ``meta`` as strict JSON (a
    float image's unknown white level, +inf in memory, is null: JSON has no infinity)."""
    return json.dumps(json_safe({FORMAT_KEY: FORMAT_VERSION, **meta}), allow_nan=False)


def white_levels(meta: dict, views: int) -> list[float]:
    """The white level of each view, +inf where the file records none (null: a float image
    decoded without --white clips nowhere)."""
    whites = meta.get("white_level") or [None] * views
    return [float("inf") if w is None else float(w) for w in whites]


def check_result(path, data: np.ndarray, meta: dict) -> None:
    """Refuse to write a result (views, rows, cols) whose views ``meta`` does not name one by one,
    that holds no valid pixel in a view, or that holds +-Inf (an overflow, never light)."""
    floats = data.dtype.kind == "f"
    check_summary(path, meta, data.shape[0],
                  [_has_finite(page) for page in data] if floats else None,
                  _first_infinite(data) if floats else None)


def check_summary(path, meta: dict, n_views: int, finite, infinite) -> None:
    """:func:`check_result` from what was learnt of the pixels: per view whether it holds a
    finite pixel (None: not float), and (view, how many, row, col) of the +-Inf pixels or None."""
    names = meta.get("views")
    if names is not None and len(names) != n_views:
        raise ValueError(f"{len(names)} view names for {n_views} views")
    names = names or [f"view {k}" for k in range(n_views)]
    for name, has_finite in zip(names, finite if finite is not None else [True] * n_views,
                                strict=True):
        if not has_finite:
            raise InputError(f"{path}: view {name} of the result holds no valid pixel (all "
                             "NaN or infinite: every input pixel clipped, masked or outside "
                             "the grid); nothing was written: check the inputs with "
                             "plenocli info")
    if infinite:  # +-Inf is never written either: an overflow, not light
        k, count, row, col = infinite
        raise InputError(f"{path}: view {names[k]} of the result holds {count} infinite "
                         f"pixels (first at row {row}, col {col}): it overflowed float32, "
                         "the inputs hold values far beyond any sensor level; nothing was "
                         "written")


SEAL_KEY = "pixels_sha256"
SEALED_META = ("views", "cfa", "origin", "mixing")  # what the pixels mean, sealed with them


def pixels_digest(data: np.ndarray, meta: dict) -> str:
    """sha256 of (views, rows, cols) ``data`` (dtype, shape, little-endian samples) and of the
    ``SEALED_META`` fields of ``meta``."""
    little = data.dtype.newbyteorder("<")
    described = json.dumps({k: meta.get(k) for k in SEALED_META}, sort_keys=True)
    digest = hashlib.sha256(f"{little.str}{tuple(data.shape)}{described}".encode())
    for page in data:
        digest.update(np.ascontiguousarray(page, dtype=little).data)
    return digest.hexdigest()


def check_seal(path, data: np.ndarray, meta: dict, remedy: str) -> None:
    """A side file plenocli wrote sealed must hold the pixels it was written with: an edit that
    keeps every other rule (flipped, shifted, pages swapped) would change a result."""
    if meta.get(SEAL_KEY) != pixels_digest(data, meta):
        state = "have no checksum" if SEAL_KEY not in meta else "no longer match their checksum"
        raise InputError(f"{path}: its pixels or views {state} ({SEAL_KEY}): the file was "
                         f"edited or damaged since plenocli wrote it; {remedy}")


def _has_finite(page: np.ndarray, rows: int = 64) -> bool:
    """Whether ``page`` holds a finite value; stops at the first band that does (cheap)."""
    return any(np.isfinite(page[r:r + rows]).any() for r in range(0, page.shape[0], rows))


class _Collect(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextlib.contextmanager
def open_tiff(path: str | os.PathLike) -> Iterator[tifffile.TiffFile]:
    """Open a TIFF whose every page header is sane (see :func:`check_page`).

    tifffile logs damage it reads past (``invalid page offset``) instead of raising: that is
    collected here (no stray line on the terminal) and becomes one InputError."""
    p = Path(path)
    logger = logging.getLogger("tifffile")
    collect, propagate = _Collect(), logger.propagate
    logger.addHandler(collect)
    logger.propagate = False
    try:
        with contextlib.ExitStack() as stack:
            try:
                tif = stack.enter_context(tifffile.TiffFile(p))
                pages = list(tif.pages)
            except TypeError as err:  # a tag of the wrong count or type: tifffile trips on it
                raise InputError(f"{p}: damaged TIFF (a malformed tag: "
                                 f"{library_words(err)}); copy or write it again") from err
            except struct.error as err:  # cut inside its header or first IFD's offset
                raise InputError(f"{p}: damaged TIFF (it ends inside its header, "
                                 f"{p.stat().st_size} bytes); the file may be truncated: copy "
                                 "or write it again") from err
            damage = [m for m in collect.messages
                      if any(w in m.lower() for w in ("offset", "truncat", "corrupt", "invalid"))]
            if damage:
                reason = plain_words(re.sub(r"<[^>]*>\s*", "", damage[0].splitlines()[0]))
                raise InputError(f"{p}: damaged TIFF ({reason}); the file may be truncated: "
                                 "copy or write it again")
            for page in pages:
                check_page(p, page)
            yield tif
    finally:
        logger.removeHandler(collect)
        logger.propagate = propagate


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, dict]:
    """Read a TIFF as (views, rows, cols) and its plenocli metadata ({} for a foreign TIFF)."""
    p = Path(path)
    if not p.is_file():
        raise not_a_file(p)
    try:
        with open_tiff(p) as tif:
            if not tif.pages:
                raise InputError(f"{p}: the TIFF holds no image")
            description = tif.pages[0].description
            series = tif.series[0] if len(tif.series) == 1 else None
            for page in tif.pages:
                check_segments(p, page)
                check_light_levels(p, page)
            if (series is not None and series.ndim == 3 and series.shape[0] == len(tif.pages)
                    and all(int(page.photometric) != 3 for page in tif.pages)):  # no table
                data = series.asarray()  # equal grey pages (plenocli's own): one read, no copy
            else:
                data = _stack_pages(p, list(tif.pages))
    except READ_ERRORS as err:
        raise read_error(p, err, f"{p}: not a readable TIFF image ({library_words(err)}); "
                                 "pass an image written by plenocli or a plain TIFF") from err
    meta = plenocli_meta(p, description)
    check_geometry(p, meta, data.shape)
    check_levels(p, meta, data.shape[0])
    whites = meta.get("white_level")
    if whites and data.dtype.kind in "ui" and None in whites:  # null: a float image's only
        raise InputError(f"{p}: white_level {whites!r} names no level for integer samples; the "
                         "file was edited or damaged: decode the capture again")
    # compared as stored (a float64): 2^64 - 1 is 2^64 there, as decode recorded it
    if whites and data.dtype.kind in "ui" and max(whites) > float(np.iinfo(data.dtype).max):
        raise InputError(f"{p}: white level {numbers([max(whites)])} is beyond what its "
                         f"{data.dtype} samples can reach, so clipped pixels would pass as light; "
                         "the file was edited or damaged: decode the capture again")
    check_no_infinity(p, data, meta.get("views"))
    return data, _camera_metadata(p, meta)


def _camera_metadata(path: Path, meta: dict) -> dict:
    """``meta`` with its camera colour and EXIF fields checked (rawmeta): a field that is not
    what it must be is dropped with a warning, so no stage trips on it."""
    if meta.get("colour") is None and meta.get("exif") is None:
        return meta
    from plenocli.io import rawmeta

    def warn(message: str) -> None:
        log.warning("%s: %s", path, message)

    meta = dict(meta)
    if "colour" in meta:
        meta["colour"] = rawmeta.clean_colour(meta["colour"], warn)
    if "exif" in meta:
        meta["exif"] = rawmeta.clean_exif(meta["exif"], warn)
    return meta


def check_no_infinity(path, data: np.ndarray, names=None) -> None:
    """Refuse a float image holding +-Inf. In plenocli NaN marks a clipped or unknown pixel and
    every stage skips it; an infinite value is never light, and passed on it spoils every sum it
    enters (a developed photograph's exposure, an unmixed view)."""
    found = _first_infinite(data)
    if found:
        k, count, row, col = found
        name = names[k] if names and k < len(names) else k
        raise InputError(f"{path}: view {name} holds {count} infinite pixels (first at row "
                         f"{row}, col {col}); plenocli reads NaN as a clipped or unknown pixel "
                         "but never +-Inf: write NaN there, or make the file again")


def _first_infinite(data: np.ndarray, rows: int = 64) -> tuple[int, int, int, int] | None:
    """(page, how many, row, col) of the first page holding +-Inf, or None. Band by band: no
    full-size temporary for the common, finite case."""
    if data.dtype.kind != "f":
        return None
    for k, page in enumerate(data.reshape(-1, *data.shape[-2:])):
        if any(np.isinf(page[r:r + rows]).any() for r in range(0, page.shape[0], rows)):
            where = np.argwhere(np.isinf(page))
            return k, len(where), int(where[0][0]), int(where[0][1])
    return None


def check_geometry(path, meta: dict, shape: tuple[int, ...]) -> None:
    """The geometry in ``meta`` must fit (views, rows, cols) ``shape``: view names one per page,
    ``active_area`` and each masked area inside the image, ``origin`` two whole numbers."""
    names = meta.get("views")
    if (names is None and "views" in meta) or (
            names is not None and (not isinstance(names, list) or len(names) != shape[0])):
        raise InputError(f"{path}: metadata names {names!r} for {shape[0]} pages; the file was "
                         "edited or damaged: write it again")
    check_view_names(path, names)
    if names is not None and len(set(map(str, names))) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise InputError(f"{path}: metadata names view {twice!r} twice; the file was edited or "
                         "damaged: write it again")
    masked = meta.get("masked_areas")
    if masked is not None and not isinstance(masked, list):
        raise InputError(f"{path}: masked area list {masked!r} is not a list of [top, left, "
                         "bottom, right] rectangles; the file was edited or damaged")
    areas = [("active_area", meta.get("active_area"))]
    areas += [("masked area", a) for a in (masked or [])]
    for what, area in areas:
        if area is None and what == "active_area":
            continue
        if not inside(area, shape[-2:]):
            raise InputError(f"{path}: {what} {area} is not a [top, left, bottom, right] "
                             f"rectangle inside the {shape[-1]} x {shape[-2]} image; the file "
                             "was edited or damaged: decode the capture again")
    active = meta.get("active_area")
    for area in (masked or []) if active is not None else ():
        if rects_overlap(area, active):
            raise InputError(f"{path}: masked area {area} overlaps active_area {active} (the "
                             "over-scan lies outside the image area); the file was edited or "
                             "damaged: decode the capture again")
    turned = meta.get("orientation")
    if turned is not None:
        try:
            orientation.check(turned)
        except ValueError as err:
            raise InputError(f"{path}: {err} in its metadata; the file was edited or damaged: "
                             "decode the capture again") from err
    origin = meta.get("origin")
    if origin is not None and not (isinstance(origin, list) and len(origin) == 2
                                   and all(isinstance(v, int) and not isinstance(v, bool)
                                           and v >= 0 for v in origin)):
        raise InputError(f"{path}: origin {origin!r} is not two whole numbers >= 0 [row, col] "
                         "(sensor coordinates)")


def check_view_names(path, names) -> None:
    """View names, when given, are a list of non-empty text."""
    if names is not None and not (isinstance(names, list)
                                  and all(isinstance(n, str) and n.strip() for n in names)):
        raise InputError(f"{path}: metadata names {names!r}: view names must be non-empty "
                         "text; the file was edited or damaged: write it again")


def check_levels(path, meta: dict, views: int) -> None:
    """CFA pattern, levels and records in ``meta`` must be what the stages read: a Bayer
    pattern or null, per view 4 finite black levels and a white level above them."""
    cfa = meta.get("cfa")
    if cfa is not None and not is_bayer(cfa):
        raise InputError(f"{path}: cfa {cfa!r} in the metadata is not a 2 x 2 Bayer pattern "
                         "(RGGB, BGGR, GRBG, GBRG); the file was edited or damaged")
    blacks, whites = meta.get("black_level"), meta.get("white_level")
    if blacks is not None and not (
            isinstance(blacks, list) and len(blacks) == views
            and all(isinstance(b, list) and len(b) == 4 and all(_finite(v) and v >= 0 for v in b)
                    for b in blacks)):
        raise InputError(f"{path}: black_level {blacks!r} is not 4 finite levels >= 0 per view "
                         f"({views} views); the file was edited or damaged")
    if whites is not None and not (
            isinstance(whites, list) and len(whites) == views
            and all(w is None or (_number(w) and w == w) for w in whites)):  # w == w: not NaN
        raise InputError(f"{path}: white_level {whites!r} is not one level per view "
                         f"({views} views); the file was edited or damaged")
    if blacks is not None and whites is not None:
        for k, (black, white) in enumerate(zip(blacks, whites, strict=True)):
            if white is not None and not white > max(black):
                raise InputError(f"{path}: view {k}: white level {white:g} is not above its "
                                 f"black level {max(black):g}; the file was edited or damaged")
    colours = meta.get("view_colours")
    if colours is not None and not (isinstance(colours, list) and len(colours) == views and all(
            c is None or (isinstance(c, str) and (is_bayer(c) or c in ("R", "G", "B")))
            for c in colours)):
        raise InputError(f"{path}: view_colours {colours!r} is not one Bayer pattern, colour "
                         f"(R, G, B: the SAIs of a per-pixel Bayer sensor) or null per view "
                         f"({views} views); the file was edited or damaged")
    for key, kind in (("provenance", dict), ("history", list)):
        if meta.get(key) is not None and not isinstance(meta[key], kind):
            raise InputError(f"{path}: {key} in the metadata is not a {kind.__name__}; the file "
                             "was edited or damaged")


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _finite(value) -> bool:
    return _number(value) and abs(value) < float("inf")


def inside(area, shape) -> bool:
    """Whether ``area`` is a [top, left, bottom, right] rectangle of whole numbers inside an
    image of (rows, cols) ``shape``."""
    if not (isinstance(area, (list, tuple)) and len(area) == 4
            and all(isinstance(v, int) and not isinstance(v, bool) for v in area)):
        return False
    top, left, bottom, right = area
    return 0 <= top < bottom <= shape[0] and 0 <= left < right <= shape[1]


def rects_overlap(a, b) -> bool:
    """Whether two [top, left, bottom, right] rectangles share a pixel."""
    return max(a[0], b[0]) < min(a[2], b[2]) and max(a[1], b[1]) < min(a[3], b[3])


def _stack_pages(path: Path, pages: list) -> np.ndarray:
    """Pages of a foreign TIFF as (views, rows, cols): each sample (R, G, B) becomes a view,
    interleaved (rows, cols, samples) or planar (samples, rows, cols)."""
    arrays = []
    for page in pages:
        data = page_levels(path, page)
        if data.ndim == 3:
            planar = page.axes.startswith("S")  # PlanarConfiguration 2: samples first
            arrays.extend(data if planar else np.moveaxis(data, -1, 0))
        else:
            arrays.append(data)
    if len({a.shape for a in arrays}) != 1:
        raise InputError(f"{path}: the pages have different sizes; plenocli expects equal-sized "
                         "views")
    return np.stack(arrays)


def read_meta(path: str | os.PathLike) -> dict:
    """Only the plenocli metadata of a TIFF (cheap: no pixel data is read)."""
    try:
        with open_tiff(path) as tif:
            description = tif.pages[0].description if tif.pages else ""
    except (*READ_ERRORS, InputError):
        return {}
    meta = plenocli_meta(path, description)
    check_view_names(path, meta.get("views"))
    return meta


def plenocli_meta(path, description: str | None) -> dict:
    """The plenocli metadata in a TIFF's description ({} for another program's description).

    A description that starts as plenocli's but is not JSON, or names another format version,
    is an InputError: its pixels would be read with the wrong geometry or levels."""
    if not description:
        return {}
    try:
        parsed = load_json(description)
    except DocumentError as err:
        if description.lstrip().startswith(f'{{"{FORMAT_KEY}"'):
            raise InputError(f"{path}: its plenocli metadata is damaged (not JSON: {err}); "
                             "write the file again") from err
        return {}
    if not isinstance(parsed, dict) or FORMAT_KEY not in parsed:
        return {}  # another program's JSON (tifffile writes {"shape": ...}) is not ours
    version = parsed[FORMAT_KEY]
    if not (isinstance(version, int) and 1 <= version <= FORMAT_VERSION):
        raise InputError(f"{path}: plenocli format {version!r}, but this plenocli reads format "
                         f"{FORMAT_VERSION}: made by another plenocli version, or damaged; "
                         "process it with the plenocli that wrote it")
    return {k: v for k, v in parsed.items() if k != FORMAT_KEY}


def history_of(source: dict) -> list:
    """The history of an output made from ``source``: its history and its own provenance."""
    history = list(source.get("history", []))
    if source.get("provenance"):
        history.append(source["provenance"])
    return history


def derived_meta(source: dict, record: dict, **changes) -> dict:
    """Metadata for an output made from ``source``: history grows, ``changes`` override keys."""
    history = history_of(source)
    meta = {k: v for k, v in source.items() if k not in ("provenance", "history", SEAL_KEY)}
    meta.update(changes)
    meta["provenance"] = record
    meta["history"] = history
    return meta
