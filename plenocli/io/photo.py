"""Output-referred images: encode linear RGB for a display space and build the file's bytes.

A 16-bit TIFF (tifffile) or an 8-bit JPEG / PNG (Pillow), each with the space's ICC profile,
the camera's EXIF tags carried over (make, model, exposure, aperture, ISO, lens, date) and the
plenocli provenance (JSON) in ImageDescription. The bytes are returned: the stage writes them
atomically.
"""

from __future__ import annotations

import functools
import io
import json
from fractions import Fraction

import numpy as np

from plenocli.io.icc import profile_bytes
from plenocli.io.rawmeta import clean_exif
from plenocli.model.colour import OUTPUT_SPACES
from plenocli.model.orientation import check

FORMATS = {".tif": "tiff", ".tiff": "tiff", ".jpg": "jpeg", ".jpeg": "jpeg", ".png": "png"}
# EXIF tags carried over: name in the frames' metadata -> (tag, TIFF type, in the EXIF sub-IFD)
EXIF_TAGS = {"Make": (271, "s", False), "Model": (272, "s", False),
             "ExposureTime": (33434, "2I", True), "FNumber": (33437, "2I", True),
             "ISO": (34855, "H", True), "DateTimeOriginal": (36867, "s", True),
             "FocalLength": (37386, "2I", True), "LensModel": (42036, "s", True)}
EXIF_IFD = 0x8769


def output_format(path: str) -> str:
    """``tiff``, ``jpeg`` or ``png`` from a file name; ValueError for anything else."""
    suffix = "." + str(path).rsplit(".", 1)[-1].lower() if "." in str(path) else ""
    if suffix not in FORMATS:
        raise ValueError(f"output {path}: unknown image type {suffix or '(none)'}; use .tif "
                         "(16-bit), .jpg or .png (8-bit)")
    return FORMATS[suffix]


def encode(rgb: np.ndarray, space: str) -> np.ndarray:
    """Linear RGB of ``space`` (..., 3), already scaled so that 1 is white, to the space's
    encoding in [0, 1]: the sRGB curve for sRGB and Display P3, none for linear Rec.2020.
    NaN (masked) pixels become 0."""
    if space not in OUTPUT_SPACES:
        raise ValueError(f"colour space {space!r} unknown; choose one of "
                         f"{', '.join(OUTPUT_SPACES)}")
    if space == "rec2020-linear":
        return np.clip(np.nan_to_num(np.asarray(rgb, np.float32), nan=0.0), 0.0, 1.0)
    x = np.ascontiguousarray(rgb, np.float32)
    out = np.empty(x.shape, np.float32)
    _srgb_kernel()(x.reshape(-1), out.reshape(-1), _srgb_table())
    return out


# The sRGB curve read from a table of 2^16 steps, linearly interpolated (within 1e-6 of the
# formula): the power function per value cost a third of developing a 30 MP frame.
_CURVE_STEPS = 1 << 16


@functools.cache
def _srgb_table() -> np.ndarray:
    x = np.linspace(0.0, 1.0, _CURVE_STEPS + 1)
    curve = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return curve.astype(np.float32)


@functools.cache
def _srgb_kernel():
    import numba  # only develop encodes: the other commands start without numba

    @numba.njit(cache=True, nogil=True)
    def srgb_curve(x, out, table):
        steps = table.size - 1
        for k in range(x.size):
            v = x[k]
            if not v > 0.0:  # NaN (masked) and negatives encode as 0
                out[k] = 0.0
            elif v >= 1.0:
                out[k] = table[steps]
            else:
                s = v * steps
                i = int(s)
                out[k] = table[i] + (s - i) * (table[i + 1] - table[i])

    return srgb_curve


def image_bytes(encoded: np.ndarray, fmt: str, *, space: str, exif: dict | None,
                description: dict, quality: int = 95, orientation: int = 1) -> bytes:
    """The bytes of an image file holding ``encoded`` (rows, cols, 3) in [0, 1], turned
    upright as the camera's ``orientation`` (1-8, model/orientation) says."""
    if fmt not in ("tiff", "jpeg", "png"):
        raise ValueError(f"fmt must be tiff, jpeg or png, got {fmt!r}")
    if fmt != "tiff" and space == "rec2020-linear":
        raise ValueError("linear Rec.2020 needs 16 bits: write a .tif, or choose --space srgb "
                         "or display-p3 for JPEG/PNG")
    icc = profile_bytes(space)
    text = json.dumps(description, allow_nan=False)
    # read through rawmeta.clean_exif already (warned there); again here for any caller
    exif = clean_exif(exif, warn=lambda message: None)
    if fmt == "tiff":
        return _tiff_bytes(encoded, icc, exif, text, orientation)
    from PIL import Image

    pixels = _upright(np.round(encoded * 255).astype(np.uint8), orientation)
    image = Image.fromarray(pixels, mode="RGB")
    pil_exif = Image.Exif()
    pil_exif[270] = text
    for name, value in exif.items():
        tag, kind, in_sub = EXIF_TAGS[name]
        target = pil_exif.get_ifd(EXIF_IFD) if in_sub else pil_exif
        target[tag] = _pil_value(value, kind)
    buffer = io.BytesIO()
    options = {"quality": int(quality), "subsampling": 0} if fmt == "jpeg" else {}
    image.save(buffer, format=fmt.upper(), icc_profile=icc, exif=pil_exif.tobytes(), **options)
    return buffer.getvalue()


def _pil_value(value, kind: str):
    if kind == "2I":
        from PIL.TiffImagePlugin import IFDRational

        f = Fraction(float(value)).limit_denominator(100000)
        return IFDRational(f.numerator, f.denominator)
    return int(value) if kind == "H" else str(value)


def _upright(pixels: np.ndarray, orientation: int) -> np.ndarray:
    """``pixels`` (rows, cols, 3; 8 or 16 bits) turned as ``orientation`` (model/orientation)
    says, as readers honouring the tag turn it (the tests hold it to Pillow's exif_transpose);
    by OpenCV, on the quantised image: numpy's strided copy of a turned 30 MP float image took
    1-2 s more."""
    import cv2

    check(orientation)
    turns = {3: cv2.ROTATE_180, 6: cv2.ROTATE_90_CLOCKWISE, 8: cv2.ROTATE_90_COUNTERCLOCKWISE}
    if orientation in turns:
        return cv2.rotate(pixels, turns[orientation])
    if orientation in (2, 4):
        return cv2.flip(pixels, 1 if orientation == 2 else 0)
    if orientation in (5, 7):
        swapped = cv2.transpose(pixels)
        return swapped if orientation == 5 else cv2.flip(swapped, -1)
    return pixels


def _tiff_bytes(encoded: np.ndarray, icc: bytes, exif: dict, text: str,
                orientation: int) -> bytes:
    import tifffile

    from plenocli import __version__

    tags = [(34675, "B", len(icc), icc, True)]  # InterColorProfile
    for name, value in exif.items():  # written in IFD 0, where TIFF readers list them
        tag, kind, _ = EXIF_TAGS[name]
        if kind == "2I":
            f = Fraction(float(value)).limit_denominator(100000)
            tags.append((tag, "2I", 1, (f.numerator, f.denominator), True))
        elif kind == "H":
            tags.append((tag, "H", 1, (int(value),), True))
        else:
            tags.append((tag, "s", 0, str(value), True))
    buffer = io.BytesIO()
    data = np.empty(encoded.shape, np.uint16)
    for start in range(0, encoded.shape[0], 256):  # band by band: no full-size float temporary
        data[start:start + 256] = np.rint(encoded[start:start + 256] * np.float32(65535))
    data = _upright(data, orientation)
    tifffile.imwrite(buffer, data, photometric="rgb", description=text, metadata=None,
                     software=f"plenocli {__version__}", extratags=sorted(tags))
    return buffer.getvalue()


def photo_record(path) -> dict | None:
    """The provenance ``develop`` writes in a photograph's ImageDescription ({"plenocli":
    record, "history": [...]}), or None."""
    from PIL import Image

    from plenocli.io.yamlfile import DocumentError, load_json

    try:
        with Image.open(path) as image:
            text = image.getexif().get(270) or image.info.get("description")
    except Exception:  # any failure of this probe: the image readers say what the file is
        return None
    try:
        doc = load_json(text) if isinstance(text, str) else None
    except DocumentError:
        return None
    return doc if isinstance(doc, dict) and isinstance(doc.get("plenocli"), dict) else None
