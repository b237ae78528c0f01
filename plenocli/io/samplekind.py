"""Which samples are light levels: one rule for every image format plenocli reads (TIFF, PNG,
BMP, and what else OpenCV decodes for calibrate, e.g. JPEG), decided from what the file
declares (TIFF Photometric and BitsPerSample, the kind and colour table Pillow reads from any
other format's header), never from its name.

- Grey, RGB (with or without alpha), a raw's CFA and LinearRaw samples are light levels.
- A palette (colour-index) image stores indices into a colour table. When every entry is grey
  (R = G = B) the table is only how the file stores a grey image (every 8-bit grey BMP has one;
  an identity ramp gives the indices themselves): its pixels are read as those greys. A table
  with any colour entry is refused: an index into colours is no light level, and reading the
  colours would invent three frames the sensor never measured.
- One bit per pixel (a 1-bit grey or bilevel image, or a table of at most two entries) is
  refused: two levels measure no light (every lit pixel sits at the white level, clipped).
- Inverted grey (MinIsWhite), CMYK, Lab, YCbCr kept as such, transparency masks, LogL/LogLuv
  and depth samples are refused.
"""

from __future__ import annotations

import numpy as np

from plenocli.errors import InputError
from plenocli.io.samplebits import png_colour_type

WHAT_TO_DO = "save the sensor image as grey or RGB"
BILEVEL = "1-bit (two-level)"
# Pillow modes whose samples are no light levels (the TIFF ones are named by Photometric)
PILLOW_NOT_LEVELS = {"CMYK": "CMYK (ink amounts)", "LAB": "CIELab", "HSV": "HSV",
                     "YCbCr": "YCbCr"}


def refusal(path, kind: str, fmt: str) -> InputError:
    """The one refusal of a sample kind that holds no light levels, in every format."""
    why = {BILEVEL: "two levels measure no light: every lit pixel is at the white level",
           "colour-palette": "its samples are indices into a table of colours"}.get(kind)
    return InputError(f"{path}: a {kind} {fmt} holds no light levels"
                      f"{f' ({why})' if why else ''}; {WHAT_TO_DO}")


def grey_table(path, table: np.ndarray, fmt: str) -> np.ndarray:
    """The grey level of each entry of a colour table (entries, 3): read through it, a palette
    image is the grey image it stores. Refused when an entry is a colour, or when the table has
    two entries or fewer (a bilevel image)."""
    table = np.asarray(table).reshape(-1, 3)
    if len(table) <= 2:
        raise refusal(path, BILEVEL, fmt)
    if not np.all(table == table[:, :1]):
        raise refusal(path, "colour-palette", fmt)
    return table[:, 0]


def tiff_grey_table(path, colormap: np.ndarray) -> np.ndarray:
    """A TIFF ColorMap (3, entries) of 16-bit values as grey levels: 8-bit greys when every
    entry is one stored the TIFF way (v * 257, or v * 256 as Pillow writes), so that one image
    reads the same as TIFF, PNG or BMP; 16-bit greys otherwise."""
    greys = grey_table(path, np.asarray(colormap, np.uint16).T, "TIFF")
    for scale in (257, 256):
        if not np.any(greys % scale):
            return (greys // scale).astype(np.uint8)
    return greys


def declared_kind(path) -> str | None:
    """What a non-TIFF image's header declares: ``"grey"`` for grey samples or a palette of grey
    entries (OpenCV decodes either through the table and may spread it over three channels),
    None for other light levels (RGB) or a format Pillow does not know (OpenCV's errors speak
    for it); a refusal for anything else."""
    import warnings

    from PIL import Image

    if png_colour_type(path) == 4:  # Pillow calls a 16-bit grey + alpha PNG "RGBA"
        return "grey"
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # a huge header: OpenCV's bound refuses it
            with Image.open(path) as image:
                mode, fmt = image.mode, image.format or "image"
                table = image.getpalette() if mode in ("P", "PA") else None
                indices = None if table is None else np.asarray(image)
                top = None if indices is None else int(
                    (indices if indices.ndim == 2 else indices[..., 0]).max())
    except Exception:  # noqa: BLE001 (any decoding error: OpenCV reads the file and says why)
        return None
    if mode == "1":
        raise refusal(path, BILEVEL, fmt)
    if mode in PILLOW_NOT_LEVELS:
        raise refusal(path, PILLOW_NOT_LEVELS[mode], fmt)
    if table is not None:
        entries = len(grey_table(path, np.asarray(table, np.uint8), fmt))
        if top >= entries:  # decoders read such an index as black: no light level
            raise InputError(f"{path}: a palette {fmt} with a pixel of index {top}, past its "
                             f"{entries}-entry table: the file is damaged; write it again")
        return "grey"
    return "grey" if mode in ("L", "LA", "La", "I", "I;16", "I;16B", "I;16L", "F") else None
