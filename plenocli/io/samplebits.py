"""How many bits of a plain image's samples carry light, as the file declares it: one rule with
a TIFF's BitsPerSample (``tiffsegments.sample_tops``). The light levels are the samples as the
sensor side wrote them and the white level is 2^bits - 1 (a 12-bit image: 4095), whatever
the word the format stores them in.

- PNG: the sBIT chunk gives the significant bits of each channel. The PNG standard has a writer
  scale such samples up to the word (12-bit 4095 -> 65535, by a shift, bit replication or a
  linear map) and a reader recover them by shifting right: every sample one of those scalings
  writes is read shifted back. Writers that store the 12 bits as they are (0-4095 in 16-bit
  words, as a 12-bit TIFF does) are known by a sample no scaling writes, every sample fitting
  in its bits; the samples are then read as stored. Either way the white is 2^sBIT - 1. Samples
  that fit neither are refused: the header and the image disagree. (A very dark image whose
  samples fit both readings, every sample below 2^(2 sBIT - word) and a multiple of the
  scaling, is read the standard's way.)
- BMP: 16-bit pixels (5-5-5, 5-6-5) and pixels given by bit masks are refused
  (:func:`refuse_masked_bmp`); other BMPs (palettes, 24-bit, 32-bit BGRA) OpenCV reads as
  they are, every sample its byte.
"""

from __future__ import annotations

import struct

import numpy as np

from plenocli.errors import InputError

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PNG_CHANNELS = {0: 1, 2: 3, 3: 3, 4: 2, 6: 4}  # colour type -> sBIT bytes (grey, RGB, palette..)
MAX_CHUNKS = 10_000   # sBIT precedes PLTE and IDAT: a file with more chunks before them is junk
BI_BITFIELDS, BI_ALPHABITFIELDS = 3, 6
PLAIN_MASKS_32 = (0xFF0000, 0xFF00, 0xFF)  # red, green, blue: the bytes of a BI_RGB pixel
Tops = list[tuple[float, str]]


def png_colour_type(path) -> int | None:
    """A PNG's colour type from its IHDR, the first chunk (0 grey, 4 grey + alpha); None for
    another file."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(26)
    except OSError:
        return None
    if len(head) < 26 or head[:8] != PNG_MAGIC or head[12:16] != b"IHDR":
        return None
    return head[25]


def png_significant_bits(path) -> tuple[list[int], int] | None:
    """The sBIT of a PNG (one entry a channel, in the file's channel order) and its IHDR bit
    depth; None without sBIT (or for a file whose chunks OpenCV's errors will describe)."""
    with open(path, "rb") as fh:
        if fh.read(8) != PNG_MAGIC:
            return None
        depth = colour = None
        palette_seen = False
        for _ in range(MAX_CHUNKS):
            head = fh.read(8)
            if len(head) < 8:
                return None
            length, kind = struct.unpack(">I4s", head)
            if kind in (b"IDAT", b"IEND"):
                return None
            if kind == b"sBIT" and palette_seen:  # libpng drops it: the levels are unknown
                raise InputError(f"{path}: its sBIT chunk comes after its palette, where the "
                                 "PNG standard does not allow it (readers ignore it); the file "
                                 "is damaged: write it again")
            palette_seen = palette_seen or kind == b"PLTE"
            body = fh.read(length) if kind in (b"IHDR", b"sBIT") else fh.seek(length, 1)
            fh.seek(4, 1)  # CRC: libpng checks it when OpenCV decodes
            if kind == b"IHDR" and len(body) >= 10:
                depth, colour = body[8], body[9]
            elif kind == b"sBIT" and depth is not None:
                return list(body), (8 if colour == 3 else depth)
    return None


def png_levels(path, data: np.ndarray, grey: bool) -> tuple[np.ndarray, Tops | None]:
    """The light levels of a PNG as OpenCV decoded it (channels last, RGB order; ``grey``: one
    plane) and each frame's white, by its sBIT (module docstring); tops None without sBIT."""
    found = png_significant_bits(path)
    if found is None:
        return data, None
    bits, depth = found
    word = 8 * data.dtype.itemsize
    planes = 1 if data.ndim == 2 else min(data.shape[2], 3)
    if not bits or any(not 0 < b <= depth for b in bits):
        raise InputError(f"{path}: its sBIT chunk declares {', '.join(map(str, bits))} "
                         f"significant bits for {depth}-bit samples (each in 1 to {depth}); the "
                         "file is damaged: write it again")
    # a grey table's entries carry the bits of R, G and B alike: its greys have the most
    bits = [max(bits[:3])] if grey and len(bits) >= 3 else bits[:planes]
    if len(bits) < planes or all(b == word for b in bits):
        return data, None
    stack = data[..., np.newaxis] if data.ndim == 2 else data[..., :planes]
    scaled = all(_scaled_form(stack[..., c], b, word) for c, b in enumerate(bits))
    fits = all(int(stack[..., c].max(initial=0)) < 2 ** b for c, b in enumerate(bits))
    if not (scaled or fits):
        raise InputError(f"{path}: samples that are neither {'/'.join(map(str, bits))}-bit "
                         f"values nor such values scaled to {word} bits as its sBIT chunk "
                         "declares; the header or the image is damaged: write it again")
    if scaled:  # the standard's way: shift the scaling out
        out = np.empty(stack.shape, data.dtype)
        for c, b in enumerate(bits):
            np.right_shift(stack[..., c], word - b, out=out[..., c])
        data = out[..., 0] if data.ndim == 2 else out
    return data, [(float(2 ** b - 1), f"{b}-bit samples (PNG sBIT {b})") for b in bits]


def _scaled_form(plane: np.ndarray, bits: int, word: int) -> bool:
    """Every sample one that scaling ``bits``-bit values up to ``word`` bits writes: by a shift,
    by bit replication, or the linear map round(v (2^word - 1) / (2^bits - 1))."""
    if bits == word:
        return True
    shift = word - bits
    plane = plane.astype(np.int64)
    original = plane >> shift
    if np.array_equal(plane, original << shift):
        return True
    copied = original << shift
    step = shift - bits
    while step > 0:
        copied |= original << step
        step -= bits
    copied |= original >> -step
    linear = np.floor(original * ((2 ** word - 1) / (2 ** bits - 1)) + 0.5).astype(np.int64)
    return bool(np.all((plane == copied) | (plane == linear)))


def refuse_masked_bmp(path) -> None:
    """InputError for a BMP of 16-bit pixels or of bit masks (BI_BITFIELDS): OpenCV, which reads
    plenocli's BMPs, shifts 5-bit samples into bytes (a white of 248 under 255) and reads masks
    it does not know as bytes (wrong colours), so their light levels cannot be vouched for.
    Such BMPs hold screen colours, not sensor data: refused, not decoded by hand. A 32-bit BMP
    whose masks are the plain layout (8 bits a colour at bits 16, 8, 0, as GIMP and Windows
    write them) OpenCV reads as stored: it is read."""
    with open(path, "rb") as fh:
        head = fh.read(14 + 40 + 12)
    if head[:2] != b"BM" or len(head) < 14 + 40:
        return
    bpp, compression = struct.unpack_from("<HI", head, 28)
    # the masks follow a 40-byte header, and sit at the same place inside a longer one
    masks = struct.unpack_from("<III", head, 54) if len(head) >= 66 else None
    if bpp == 32 and masks == PLAIN_MASKS_32:
        return
    if bpp == 16 or compression in (BI_BITFIELDS, BI_ALPHABITFIELDS):
        what = "16-bit pixels" if bpp == 16 else "pixels given by bit masks"
        raise InputError(f"{path}: a BMP of {what}, whose samples OpenCV does not read as "
                         "stored; write the image as a PNG or TIFF")
