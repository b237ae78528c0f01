"""Colour and EXIF metadata of raw captures, for ``plenocli develop``: as-shot white balance,
the XYZ -> camera matrix, and the camera's EXIF tags (make, model, exposure, lens, date).

Whatever a raw's header or a file's metadata holds goes through :func:`clean_colour` and
:func:`clean_exif` where it is read: a value that is not what its field must be is dropped with
a warning naming it (a photograph without an ISO is still right; one with a made-up white
balance is not, so develop then asks for ``--wb``)."""

from __future__ import annotations

import math
import re
import struct

import numpy as np
import tifffile

from plenocli.model.colour import MAX_GAIN_RATIO
from plenocli.progress import log

# EXIF fields carried to the photograph and what each must be. Text is ASCII (EXIF's type) and
# short (a JPEG's EXIF block holds 64 KiB);
# rationals are written with denominators up to 1e5, so they must lie in [1e-5, 1e6].
EXIF_TEXT = {"Make": 255, "Model": 255, "LensModel": 255}
EXIF_RATIONAL = ("ExposureTime", "FNumber", "FocalLength")
RATIONAL_RANGE = (1e-5, 1e6)
ISO_RANGE = (1, 65535)  # EXIF ISOSpeedRatings is a SHORT
EXIF_DATE = re.compile(r"\d{4}:\d{2}:\d{2} \d{2}:\d{2}:\d{2}")


def _tag(page, code, default=None):
    tag = page.tags.get(code)
    return default if tag is None else tag.value


def rawpy_colour(raw, desc: str) -> dict:
    """As-shot white balance (R, G, B multipliers) and XYZ -> camera matrix (rows R, G, B)."""
    index = [desc.index(c) for c in "RGB"] if set("RGB") <= set(desc) else None
    wb_all, matrix_all = (getattr(raw, "camera_whitebalance", None),
                          getattr(raw, "rgb_xyz_matrix", None))
    if index is None or wb_all is None or matrix_all is None:
        return {"as_shot_wb": None, "xyz_to_camera": None}
    wb = [float(wb_all[i]) for i in index]
    matrix = np.asarray(matrix_all, np.float64)[index]
    return {"as_shot_wb": wb if any(wb) else None,  # LibRaw's zeros: no as-shot balance
            "xyz_to_camera": matrix.tolist() if np.any(matrix) else None}


def camera_exif(path) -> dict:
    """Make, model, exposure, aperture, ISO, focal length, lens and date of a TIFF-based raw
    (CR2, DNG); absent tags are left out."""
    out = {}
    try:
        with tifffile.TiffFile(path) as tif:
            tags = tif.pages[0].tags
            exif = tags["ExifTag"].value if "ExifTag" in tags else {}
            exif = exif if isinstance(exif, dict) else {}  # a damaged EXIF IFD: none
            for name in ("Make", "Model"):
                if name in tags:
                    out[name] = exif_text(tags[name].value)
            if "Model" not in out and 50708 in tags:  # DNG UniqueCameraModel
                out["Model"] = exif_text(tags[50708].value)
    except (tifffile.TiffFileError, ValueError, OSError, IndexError, KeyError, struct.error):
        return out
    for name, key in (("ExposureTime", "ExposureTime"), ("FNumber", "FNumber"),
                      ("FocalLength", "FocalLength")):
        value = exif.get(key)
        if isinstance(value, tuple) and len(value) == 2 and value[1]:
            out[name] = value[0] / value[1]
    for name, key in (("ISO", "ISOSpeedRatings"), ("LensModel", "LensModel"),
                      ("DateTimeOriginal", "DateTimeOriginal")):
        value = exif.get(key)
        if isinstance(value, (tuple, list)):  # ISO may list several values
            value = value[0] if value else None
        value = exif_text(value) if isinstance(value, (str, bytes)) else value
        if value not in (None, ""):
            out[name] = value
    return out


def exif_text(value):
    """A text tag's value as text: ASCII bytes (a writer may type Make or Model BYTE or
    UNDEFINED) are decoded, NULs and spaces around it stripped. Bytes that are not printable
    ASCII stay bytes: :func:`clean_exif` drops them with a warning, never as Python's repr."""
    if isinstance(value, bytes):
        trimmed = value.strip(b"\0 ")
        if not (trimmed.isascii() and trimmed.decode("ascii").isprintable()):
            return value
        value = trimmed.decode("ascii")
    return str(value).strip("\0 ")


def dng_numbers(values, count: int) -> list[float] | None:
    """A (S)RATIONAL tag of ``count`` values as floats (tifffile gives numerator, denominator
    pairs); one of another count is given as it is, for :func:`clean_colour` to drop with a
    warning naming it (a ColorMatrix of 6 values, an AsShotNeutral of 4)."""
    if values is None:
        return None
    flat = [float(v) for v in np.ravel(values)]
    if len(flat) != count and len(flat) % 2 == 0:
        flat = [n / d if d else float("nan") for n, d in zip(flat[::2], flat[1::2], strict=True)]
    return flat


def dng_colour(raw_page, main_page) -> dict:
    """DNG AsShotNeutral (as R, G, B gains) and the ColorMatrix for D65 (or the last one)."""
    neutral = dng_numbers(_tag(raw_page, 50728, _tag(main_page, 50728, None)), 3)
    wb = None
    if neutral is None and _tag(raw_page, 50729, _tag(main_page, 50729, None)) is not None:
        log.warning("the DNG gives its as-shot white as AsShotWhiteXY, which plenocli does not "
                    "read (nor does LibRaw): develop needs --wb R,G,B or --wb-from WHITE.tif")
    if neutral is not None:  # checked by clean_colour: a zero or negative neutral is dropped
        with np.errstate(divide="ignore", invalid="ignore"):
            wb = (np.float64(neutral[1]) / np.asarray(neutral, np.float64)).tolist()
    matrix = bad = None
    for code, illuminant in ((50721, 50778), (50722, 50779)):  # ColorMatrix1, 2
        values = dng_numbers(_tag(raw_page, code, _tag(main_page, code, None)), 9)
        if values is not None and len(values) != 9:
            bad = values  # said and dropped by clean_colour when no other matrix is right
        elif values is not None:
            matrix = np.asarray(values, np.float64).reshape(3, 3).tolist()
            if _tag(raw_page, illuminant, _tag(main_page, illuminant, 0)) == 21:  # D65
                break
    return {"as_shot_wb": wb, "xyz_to_camera": matrix if matrix is not None else bad}


def _finite_numbers(value, count: int) -> list[float] | None:
    if not isinstance(value, (list, tuple)) or len(value) != count:
        return None
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return None
    numbers = [float(v) for v in value]
    return numbers if all(math.isfinite(v) for v in numbers) else None


def clean_colour(colour, warn) -> dict | None:
    """``colour`` metadata with the fields that are what they must be: ``as_shot_wb`` three
    finite positive gains (R, G, B), ``xyz_to_camera`` a finite 3 x 3 matrix. ``warn(message)``
    is called for each field dropped."""
    if colour is None:
        return None
    if not isinstance(colour, dict):
        warn(f"colour metadata {_shown(colour)} is not a mapping; dropped")
        return None
    out = dict(colour)
    wb = colour.get("as_shot_wb")
    if wb is not None:
        gains = _finite_numbers(wb, 3)
        if gains is None or min(gains) <= 0:
            warn(f"as-shot white balance {_shown(wb)} is not three positive gains R,G,B; "
                 "dropped (give develop --wb)")
            out["as_shot_wb"] = None
        elif max(gains) > MAX_GAIN_RATIO * min(gains):
            warn(f"as-shot white balance {_shown(wb)} has one gain more than "
                 f"{MAX_GAIN_RATIO:g} times another, beyond any light source; dropped (give "
                 "develop --wb)")
            out["as_shot_wb"] = None
    matrix = colour.get("xyz_to_camera")
    if matrix is not None:
        rows = matrix if isinstance(matrix, (list, tuple)) and len(matrix) == 3 else None
        if rows is None or any(_finite_numbers(r, 3) is None for r in rows):
            warn(f"camera colour matrix {_shown(matrix)} is not a finite 3 x 3 matrix; dropped "
                 "(develop --matrix none)")
            out["xyz_to_camera"] = None
    return out


def clean_exif(exif, warn) -> dict:
    """The EXIF fields plenocli carries (see EXIF_TEXT, EXIF_RATIONAL, ISO, DateTimeOriginal)
    that are valid for their tag; ``warn(message)`` for each one dropped. Unknown keys are
    dropped silently (they are not carried)."""
    if exif is None:
        return {}
    if not isinstance(exif, dict):
        warn(f"EXIF metadata {_shown(exif)} is not a mapping; dropped")
        return {}
    out = {}
    for name, value in exif.items():
        reason = _exif_problem(name, value)
        if reason is None:
            out[name] = value
        elif reason:
            warn(f"EXIF {name} {_shown(value)} {reason}; dropped")
    return out


def _exif_problem(name: str, value) -> str | None:
    """Why ``value`` cannot be EXIF ``name`` ("" for a field plenocli does not carry), or
    None when it can."""
    if name in EXIF_TEXT or name == "DateTimeOriginal":
        longest = EXIF_TEXT.get(name, 19)
        if not (isinstance(value, str) and value.isascii() and value.isprintable()
                and 0 < len(value) <= longest):
            return f"is not printable ASCII text of at most {longest} characters"
        if name == "DateTimeOriginal" and not EXIF_DATE.fullmatch(value):
            return "is not an EXIF date (YYYY:MM:DD HH:MM:SS)"
        return None
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if name == "ISO":
        low, high = ISO_RANGE
        ok = number and math.isfinite(value) and value == int(value) and low <= value <= high
        return None if ok else f"is not a whole ISO speed in [{low}, {high}]"
    if name in EXIF_RATIONAL:
        low, high = RATIONAL_RANGE
        ok = number and math.isfinite(value) and low <= value <= high
        return None if ok else f"is not a number in [{low:g}, {high:g}]"
    return ""


def _shown(value, limit: int = 40) -> str:
    if isinstance(value, (bytes, bytearray)):  # no b'...' repr: say what it is
        return f"(a {len(value)}-byte value)"
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."
