"""TIFF page checks made before any pixel is read: sizes against a sane bound and the file,
sample types, and each segment (strip or tile) against what the header says it holds.

tifffile decodes what the header says and pads, crops or reinterprets what does not fit: a
damaged header would give made-up pixels without an error. Every rule here is the TIFF 6 /
DNG one, checked on the header and on the segments' own headers (JPEG frames) or sizes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from plenocli.errors import InputError, library_words
from plenocli.io import samplekind

# Sizes read from a header are checked before anything is allocated: 2^30 pixels (1 Gpx) per
# page is 30 times a full-frame raw; a larger claim is damage, not a sensor.
MAX_PAGE_PIXELS = 2 ** 30
COMPRESSION_NONE = 1
# JPEG (lossless in raw DNGs, baseline in other TIFFs) and DNG 1.4's lossy JPEG.
JPEG_COMPRESSIONS = (7, 34892)
JPEG_START_OF_SCAN, JPEG_END_OF_IMAGE = b"\xff\xda", b"\xff\xd9"
JPEG_FRAME_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}  # SOF0..SOF15
# Byte codecs whose output size tifffile pads or crops to the segment's (LZW, Deflate, PackBits,
# LZMA, Zstandard): the decoded size of a segment is checked against the header's.
BYTE_CODECS = frozenset({5, 8, 32946, 32773, 34925, 50000})
# Photometric values whose samples are light levels: grey, RGB, a raw's CFA and LinearRaw (and
# YCbCr as JPEG codes it, which the codec returns as RGB); a palette of grey entries is read
# through its table (``samplekind``, the rule of every format); anything else is named, never read.
LIGHT_LEVELS = (1, 2, 32803, 34892)
PALETTE = 3
NOT_LEVELS = {0: "MinIsWhite (inverted)", 4: "transparency-mask",
              5: "CMYK (separated: ink amounts)", 6: "YCbCr",
              8: "CIELab", 9: "ICCLab", 10: "ITULab", 32844: "LogL", 32845: "LogLuv",
              51177: "depth"}
JPEG = 7
# Codes defined for bilevel (1-bit) images only: on samples of more bits the header is lying
CCITT = {2: "CCITT RLE", 3: "CCITT Group 3 fax", 4: "CCITT Group 4 fax", 32771: "CCITT RLEW"}
MAX_SAMPLE_VALUE = 281
MINISBLACK = 1
TRANSPARENCY_MASK = 4  # NewSubfileType bit 2 (bit 0, 1: a reduced-resolution preview)
ALPHA = (1, 2)  # ExtraSamples: associated, unassociated alpha (0, unspecified, is data)


def check_page(path: Path, page) -> None:
    """Refuse a page whose header claims more than MAX_PAGE_PIXELS, a sample type that is not a
    real number (complex, bool), or uncompressed pixel data beyond the end of the file."""
    try:
        shape = tuple(int(v) for v in page.shape)
        compression = int(page.compression)
    except (TypeError, ValueError) as err:
        raise InputError(f"{path}: damaged TIFF (a malformed tag: {library_words(err)}); copy or "
                         "write it again") from err
    pixels = int(np.prod(shape, dtype=np.float64))
    if pixels > MAX_PAGE_PIXELS:
        raise InputError(f"{path}: the TIFF header claims an image of {' x '.join(map(str, shape))}"
                         f" samples, more than plenocli reads ({MAX_PAGE_PIXELS} per page); the "
                         "file is damaged or not a sensor image")
    if int(page.subfiletype) & TRANSPARENCY_MASK:
        return  # 1-bit beside the image by the TIFF standard; no reader takes it for an image
    if int(page.bitspersample) == 1:  # bool to tifffile: the rule of every format names it
        raise samplekind.refusal(path, samplekind.BILEVEL, "TIFF")
    _check_compression(path, page, compression)
    if page.dtype is None:
        raise InputError(f"{path}: BitsPerSample {page.bitspersample} with SampleFormat "
                         f"{int(page.sampleformat)} is no sample type a TIFF holds; the header "
                         "is damaged: copy or write it again")
    check_real_dtype(path, page.dtype)
    if page.databytecounts:
        _check_segment_layout(path, page)
        size = Path(path).stat().st_size
        end = max(int(o) + int(c) for o, c in zip(page.dataoffsets, page.databytecounts,
                                                   strict=True))
        if end > size:
            raise InputError(f"{path}: truncated TIFF (the header places pixel data up to byte "
                             f"{end}, the file has {size} bytes); copy or write it again")
        if compression == COMPRESSION_NONE:
            _check_uncompressed_size(path, page)


def _check_compression(path, page, compression: int) -> None:
    """A Compression this reader knows and that fits the samples: a CCITT code (1-bit images
    only) on wider samples decodes to 0/1 or zeros without an error."""
    import tifffile

    bits = int(page.bitspersample)
    if compression in CCITT:
        raise InputError(f"{path}: Compression {compression} ({CCITT[compression]}, a code for "
                         f"1-bit images) on {bits}-bit samples; the header is damaged (a wrong "
                         "Compression tag): copy or write the file again")
    if compression != COMPRESSION_NONE and compression not in tifffile.TIFF.DECOMPRESSORS:
        raise InputError(f"{path}: Compression {compression}, a code no TIFF reader knows; the "
                         "file is damaged or written by a program of its own: save it "
                         "uncompressed")


def _check_segment_layout(path, page) -> None:
    """As many segments as the size and the tile size / RowsPerStrip give (TIFF 6), none of
    them inside the file header or this page's IFD: a size, tile or offset tag changed by
    damage would otherwise place decoded pixels in the wrong rows."""
    planes = int(page.samplesperpixel) if int(page.planarconfig) == 2 else 1
    rows, cols = int(page.imagelength), int(page.imagewidth)
    if page.is_tiled:
        kind, across = "tile", (int(page.tilewidth), int(page.tilelength))
    else:
        kind, across = "strip", (cols, int(page.rowsperstrip))
    if min(across) <= 0:
        raise InputError(f"{path}: damaged TIFF (a {kind} size of {across[0]} x {across[1]}); "
                         "copy or write it again")
    expected = -(-cols // across[0]) * -(-rows // across[1]) * planes
    if len(page.dataoffsets) != expected:
        raise InputError(f"{path}: damaged TIFF ({len(page.dataoffsets)} {kind}s where a "
                         f"{cols} x {rows} image in {kind}s of {across[0]} x "
                         f"{min(across[1], rows)} needs {expected}: a wrong size or {kind} "
                         "tag); copy or write it again")
    fmt = page.parent.tiff
    ifd_end = (page.offset + fmt.tagnosize + len(page.tags) * fmt.tagsize + fmt.offsetsize)
    header = 16 if fmt.version == 43 else 8
    for k, (offset, count) in enumerate(zip(page.dataoffsets, page.databytecounts,
                                            strict=True)):
        if int(offset) < header or (int(offset) < ifd_end and int(offset) + int(count)
                                    > page.offset):
            raise InputError(f"{path}: damaged TIFF ({kind} {k} at byte {int(offset)} lies in "
                             "the file's header or directory: a wrong offset); copy or write "
                             "it again")


def _check_uncompressed_size(path, page) -> None:
    """Uncompressed pixel data must be exactly what the size and BitsPerSample say (rows
    packed to whole bytes; a last strip may be written whole): fewer bytes is a cut file, more
    a header whose BitsPerSample or size is wrong (the pixels would be read misaligned)."""
    per_pixel = 1 if int(page.planarconfig) == 2 else int(page.samplesperpixel)
    planes = int(page.samplesperpixel) if int(page.planarconfig) == 2 else 1
    bits = int(page.bitspersample)
    if page.is_tiled:
        tile = int(page.tilelength) * -(-int(page.tilewidth) * per_pixel * bits // 8)
        allowed = {len(page.databytecounts) * tile}
    else:
        rows, row_bytes = int(page.imagelength), -(-int(page.imagewidth) * per_pixel * bits // 8)
        strip = min(int(page.rowsperstrip), rows)
        allowed = {planes * rows * row_bytes, planes * -(-rows // strip) * strip * row_bytes}
    held = sum(int(c) for c in page.databytecounts)
    if held not in allowed:
        what = "truncated" if held < min(allowed) else "damaged"
        raise InputError(f"{path}: {what} TIFF (uncompressed pixel data of {held} bytes where "
                         f"its size and {bits} bits per sample need {min(allowed)}); copy or "
                         "write it again")


def check_segments(path, page) -> None:
    """Refuse a page with a tile or strip that would decode to made-up pixels without an error.

    tifffile fills a segment of no bytes with zeros and decodes whatever a wrong offset points
    at (segments of one page never share bytes); libjpeg-turbo and the lossless-JPEG decoder
    fill a cut JPEG stream with made-up values, and tifffile casts JPEG samples of more bits than
    BitsPerSample says into the smaller type. A whole JPEG stream ends with its end marker, after
    its first start-of-scan (byte stuffing keeps the marker out of the coded data)."""
    kind = "tile" if page.is_tiled else "strip"
    counts = [int(c) for c in page.databytecounts]
    if 0 in counts:
        raise InputError(f"{path}: damaged TIFF ({kind} {counts.index(0)} has no data: byte count "
                         "0); copy or write the file again")
    spans = sorted(zip((int(o) for o in page.dataoffsets), counts, strict=True))
    for (start, count), (following, _) in zip(spans, spans[1:], strict=False):
        if start + count > following:  # LZW, PackBits, ... would decode one tile twice
            raise InputError(f"{path}: damaged TIFF (two {kind}s share the bytes at "
                             f"{following}: a wrong offset or byte count); copy or write the "
                             "file again")
    if int(page.compression) in BYTE_CODECS:
        _check_decoded_sizes(path, page, kind)
    if int(page.compression) not in JPEG_COMPRESSIONS:
        return
    handle = page.parent.filehandle
    for k, (offset, count) in enumerate(zip(page.dataoffsets, counts, strict=True)):
        handle.seek(offset)
        segment = handle.read(count)
        scan = segment.find(JPEG_START_OF_SCAN)
        if scan < 0 or segment.rfind(JPEG_END_OF_IMAGE) < scan:
            # a few cameras end whole streams without it (some Leica DNGs): no way to tell
            raise InputError(f"{path}: JPEG {kind} {k} has no end-of-image marker (cut short, "
                             "a wrong byte count, or a camera that omits it), so its last rows "
                             "cannot be trusted; copy the file again, or re-save it with Adobe "
                             "DNG Converter")
        frame = _jpeg_frame(segment)
        if frame is None:
            continue
        bits, samples = frame
        if bits > 8 * page.dtype.itemsize:
            raise InputError(f"{path}: damaged TIFF (JPEG {kind} {k} holds {bits}-bit samples, "
                             f"the header says {page.bitspersample} bits per sample); copy or "
                             "write the file again")
        if samples not in _segment_samples(page, k):
            raise InputError(f"{path}: damaged TIFF (JPEG {kind} {k} codes {samples} samples, "
                             f"the header's {kind} size holds {max(_segment_samples(page, k))}:"
                             " a wrong tile size or RowsPerStrip); copy or write the file again")


def _segment_samples(page, k: int) -> tuple[int, ...]:
    """The sample counts a JPEG segment of ``page`` may code (DNG lets a lossless-JPEG tile
    code them in any shape): a whole tile, or a strip's rows (the last one cut or whole)."""
    planar = int(page.planarconfig) == 2
    per_pixel = 1 if planar else int(page.samplesperpixel)
    if page.is_tiled:
        return (int(page.tilelength) * int(page.tilewidth) * per_pixel,)
    rows, per_row = int(page.imagelength), int(page.imagewidth) * per_pixel
    strip = min(int(page.rowsperstrip), rows)
    first_row = (k % -(-rows // strip)) * strip
    return (strip * per_row, min(strip, rows - first_row) * per_row)


def _jpeg_frame(stream: bytes) -> tuple[int, int] | None:
    """(bits per sample, rows x cols x components) of a JPEG stream's frame header (SOFn);
    None if there is none."""
    pos = 2  # after the start-of-image marker
    while pos + 5 <= len(stream) and stream[pos] == 0xFF:
        marker = stream[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
        elif marker in JPEG_FRAME_MARKERS:
            head = stream[pos + 4:pos + 10]
            if len(head) < 6:
                return None
            rows, cols = int.from_bytes(head[1:3], "big"), int.from_bytes(head[3:5], "big")
            return head[0], rows * cols * head[5]
        elif marker == JPEG_START_OF_SCAN[1]:
            return None
        else:
            pos += 2 + int.from_bytes(stream[pos + 2:pos + 4], "big")
    return None


def check_real_dtype(path, dtype) -> None:
    """Sensor and plenocli images hold real numbers: unsigned or 16+ bit integers, or floats."""
    dtype = np.dtype(dtype) if dtype is not None else None
    if dtype is None or dtype.kind not in "uif" or (dtype.kind == "i" and dtype.itemsize < 2):
        raise InputError(f"{path}: samples of type {dtype} are not real-valued sensor data "
                         "(expected unsigned integers, 16/32-bit integers or floats)")


def _check_decoded_sizes(path, page, kind: str) -> None:
    """The first and last segments of a byte codec must decode to the header's segment size
    (a tile; a strip's rows, the last one cut or whole): tifffile crops or pads any other size
    silently, which shifts every row when the width or BitsPerSample tag is wrong. Two
    segments cost little and catch a wrong header (each segment holds the same layout)."""
    import tifffile

    decompress = tifffile.TIFF.DECOMPRESSORS[int(page.compression)]
    per_pixel = 1 if int(page.planarconfig) == 2 else int(page.samplesperpixel)
    bits = int(page.bitspersample)
    handle = page.parent.filehandle
    for k in sorted({0, len(page.dataoffsets) - 1}):
        handle.seek(int(page.dataoffsets[k]))
        try:
            held = len(decompress(handle.read(int(page.databytecounts[k]))))
        except Exception:  # noqa: BLE001 (the codec's own damage errors): tifffile reports it
            return
        allowed = {samples * bits // 8 for samples in _segment_samples(page, k)}
        if per_pixel * bits % 8 and not page.is_tiled:
            allowed = {_packed_rows(page, n) for n in _segment_samples(page, k)}
        if held not in allowed:
            raise InputError(f"{path}: damaged TIFF ({kind} {k} decodes to {held} bytes where "
                             f"the header's size and {bits} bits per sample give "
                             f"{max(allowed)}: damaged data or a wrong size tag); copy or write "
                             "it again")


def _packed_rows(page, samples: int) -> int:
    """Bytes of ``samples`` of packed sub-byte or odd-bit rows (each row padded to a byte)."""
    per_row = int(page.imagewidth) * (1 if int(page.planarconfig) == 2
                                      else int(page.samplesperpixel))
    return samples // per_row * -(-per_row * int(page.bitspersample) // 8)


def check_light_levels(path, page) -> None:
    """A page whose samples are not light levels (inverted grey, CMYK ink, Lab, a palette with
    a colour entry) is refused, by the rule of every format (``samplekind``)."""
    photometric = int(page.photometric)
    if photometric in LIGHT_LEVELS or (photometric == 6 and int(page.compression) == JPEG):
        return
    if photometric == PALETTE:
        samplekind.tiff_grey_table(path, page.colormap)
        return
    kind = NOT_LEVELS.get(photometric, f"Photometric {photometric}")
    raise samplekind.refusal(path, kind, "TIFF")


def page_levels(path, page) -> np.ndarray:
    """A page's samples as light levels: a palette of grey entries read through its table
    (checked by :func:`check_light_levels`), a grey page whose extra samples are alpha as its
    grey (as a grey + alpha PNG is read), any other page as stored."""
    data = page.asarray()
    if int(page.photometric) == PALETTE:
        return samplekind.tiff_grey_table(path, page.colormap)[data]
    if (int(page.photometric) == MINISBLACK and "S" in page.axes and page.extrasamples
            and all(int(kind) in ALPHA for kind in page.extrasamples)):
        return np.take(data, 0, axis=page.axes.index("S"))
    return data


def sample_tops(path, page) -> list[tuple[float, str]] | None:
    """The largest level each sample of an integer page can hold, and what says so: its
    MaxSampleValue (tag 281), else 2^BitsPerSample - 1 (a 12-bit TIFF stores 0-4095 in 16-bit
    words: its white is 4095, as a DNG's without WhiteLevel); None for floats and palettes
    (their levels are the table's). A MaxSampleValue beyond the bits is damage."""
    if page.dtype is None or page.dtype.kind not in "ui" or int(page.photometric) == PALETTE:
        return None
    bits, count = int(page.bitspersample), int(page.samplesperpixel)
    # a signed sample spends one bit on the sign: int16 reaches 32767
    full = float(2 ** (bits - (page.dtype.kind == "i")) - 1)
    tag = page.tags.get(MAX_SAMPLE_VALUE)
    if tag is None:
        said = page.dtype if bits == 8 * page.dtype.itemsize else f"{bits}-bit"
        return [(full, f"{said} samples")] * count
    values = [float(v) for v in np.ravel(tag.value)]
    values = values * count if len(values) == 1 else values
    if len(values) != count or not all(0 < v <= full for v in values):
        raise InputError(f"{path}: MaxSampleValue {', '.join(f'{v:g}' for v in values)} for "
                         f"{count} samples of {bits} bits (each in 1 to {full:g}); the header "
                         "is damaged: copy or write it again")
    return [(v, f"samples (MaxSampleValue {v:g})") for v in values]
