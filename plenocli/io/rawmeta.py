"""Colour and EXIF metadata of raw captures, for ``plenocli develop``: as-shot white balance,
the XYZ -> camera matrix, and the camera's EXIF tags (make, model, exposure, lens, date)."""

from __future__ import annotations

import numpy as np
import tifffile


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
    return {"as_shot_wb": wb if min(wb) > 0 else None,
            "xyz_to_camera": matrix.tolist() if np.any(matrix) else None}


def camera_exif(path) -> dict:
    """Make, model, exposure, aperture, ISO, focal length, lens and date of a TIFF-based raw
    (CR2, DNG); absent tags are left out."""
    out = {}
    try:
        with tifffile.TiffFile(path) as tif:
            tags = tif.pages[0].tags
            exif = tags["ExifTag"].value if "ExifTag" in tags else {}
            for name in ("Make", "Model"):
                if name in tags:
                    out[name] = str(tags[name].value).strip("\0 ")
            if "Model" not in out and 50708 in tags:  # DNG UniqueCameraModel
                out["Model"] = str(tags[50708].value).strip("\0 ")
    except (tifffile.TiffFileError, ValueError, OSError, IndexError, KeyError):
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
        if isinstance(value, bytes):
            value = value.decode("ascii", "replace").strip("\0 ")
        if value not in (None, ""):
            out[name] = int(value) if name == "ISO" else str(value)
    return out


def dng_numbers(values, count: int) -> list[float] | None:
    """A (S)RATIONAL tag as floats (tifffile gives numerator, denominator pairs)."""
    if values is None:
        return None
    flat = [float(v) for v in np.ravel(values)]
    if len(flat) == 2 * count:
        flat = [n / d if d else float("nan") for n, d in zip(flat[::2], flat[1::2], strict=True)]
    return flat if len(flat) == count else None


def dng_colour(raw_page, main_page) -> dict:
    """DNG AsShotNeutral (as R, G, B gains) and the ColorMatrix for D65 (or the last one)."""
    neutral = dng_numbers(_tag(raw_page, 50728, _tag(main_page, 50728, None)), 3)
    wb = None
    if neutral is not None and len(neutral) == 3 and min(float(v) for v in neutral) > 0:
        wb = [float(neutral[1]) / float(v) for v in neutral]
    matrix = None
    for code, illuminant in ((50721, 50778), (50722, 50779)):  # ColorMatrix1, 2
        values = dng_numbers(_tag(raw_page, code, _tag(main_page, code, None)), 9)
        if values is not None:
            matrix = np.asarray(values, np.float64).reshape(3, 3).tolist()
            if _tag(raw_page, illuminant, _tag(main_page, illuminant, 0)) == 21:  # D65
                break
    return {"as_shot_wb": wb, "xyz_to_camera": matrix}
