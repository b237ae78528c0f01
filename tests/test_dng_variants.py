"""DNG and TIFF variants cameras and converters write, through ``plenocli decode`` (the CLI):
every lossless one gives exactly the frame it was made from; lossy JPEG gives what the file
holds; damaged or unsupported ones are refused with one line, nothing left behind.

The files are written here with tifffile and imagecodecs from seeded frames; DNG tags tifffile
will not write for one sample (LinearRaw) and damage are patched into the bytes afterwards.
"""

from __future__ import annotations

import struct
from pathlib import Path

import imagecodecs
import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import InputError
from plenocli.io import raw, tiffio

ROWS, COLS = 75, 101  # not a multiple of any tile or strip below
LINEAR_RAW = 34892
LOSSLESS_JPEG = {"compression": "jpeg", "compressionargs": {"lossless": True}}


def _frame(dtype=np.uint16, high=16384, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if np.dtype(dtype).kind == "f":
        return (rng.random((ROWS, COLS)) * 4000).astype(dtype)
    return rng.integers(0, high, (ROWS, COLS)).astype(dtype)


def _dng_tags(cfa: bool, white: int | None) -> list:
    tags = [(50706, "B", 4, (1, 4, 0, 0), True), (50707, "B", 4, (1, 4, 0, 0), True),
            (50708, "s", 0, "variants", True)]
    if white is not None:
        tags.append((50717, "I", 1, (white,), True))
    if cfa:
        tags += [(33421, "H", 2, (2, 2), True), (33422, "B", 4, (0, 1, 1, 2), True)]
    return tags


def _write_dng(path: Path, frame, *, linear: bool = False, subifd: bool = False,
               byteorder: str = "<", bigtiff: bool = False, white: int | None = 65535,
               extratags=(), **options):
    """A one-frame DNG: CFA, or LinearRaw (written as grey, then its Photometric patched)."""
    tags = _dng_tags(cfa=not linear, white=white) + list(extratags)
    with tifffile.TiffWriter(path, byteorder=byteorder, bigtiff=bigtiff) as writer:
        if subifd:  # as converters do: a JPEG preview on top, the raw in its SubIFD
            preview = np.random.default_rng(1).integers(0, 255, (24, 32, 3), dtype=np.uint8)
            writer.write(preview, photometric="rgb", subfiletype=1, subifds=1, metadata=None,
                         compression="jpeg", extratags=tags[:3])
            tags = tags[3:]
        writer.write(frame, photometric="minisblack" if linear else 32803, subfiletype=0,
                     metadata=None, extratags=tags, **options)
    if linear:
        _patch_raw_tag(path, 262, LINEAR_RAW)


def _raw_page(tif: tifffile.TiffFile):
    pages = list(tif.pages) + [sub for page in tif.pages if page.subifds for sub in page.pages]
    return next(p for p in pages if not int(p.subfiletype) & 1)


def _patch_raw_tag(path: Path, code: int, value: int, index: int = 0) -> None:
    """Write ``value`` as entry ``index`` of the raw IFD's tag ``code`` (in place)."""
    with tifffile.TiffFile(path) as tif:
        tag = _raw_page(tif).tags[code]
        size = {3: 2, 4: 4, 16: 8}[int(tag.dtype)]  # SHORT, LONG, LONG8
        fmt = tif.byteorder + {2: "H", 4: "I", 8: "Q"}[size]
        offset = tag.valueoffset + index * size
    data = bytearray(path.read_bytes())
    data[offset:offset + size] = struct.pack(fmt, value)
    path.write_bytes(bytes(data))


def _segments(path: Path) -> tuple[list[int], list[int]]:
    with tifffile.TiffFile(path) as tif:
        page = _raw_page(tif)
        return [int(v) for v in page.dataoffsets], [int(v) for v in page.databytecounts]


def _decode(path: Path, out: Path):
    result = CliRunner().invoke(cli, ["decode", str(path), "-o", str(out)])
    assert "Traceback" not in result.output + result.stderr
    return result


def _assert_refused(path: Path, tmp_path: Path, *words: str) -> None:
    out = tmp_path / "out"
    out.mkdir()
    result = _decode(path, out / "frames.tif")
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert result.exit_code == 1 and len(lines) == 1, result.output + result.stderr
    for word in words:
        assert word in lines[0], (word, lines[0])
    assert not list(out.iterdir()), "a file was left behind"


LOSSLESS = {
    "lossless JPEG tiles, odd tile": (_frame(), dict(tile=(16, 48), **LOSSLESS_JPEG)),
    "lossless JPEG strips, 14 bit": (_frame(), dict(
        rowsperstrip=32, compression="jpeg",
        compressionargs={"lossless": True, "bitspersample": 14})),
    "lossless JPEG 12 bit": (_frame(high=4096), dict(
        tile=(32, 32), compression="jpeg",
        compressionargs={"lossless": True, "bitspersample": 12})),
    "lossless JPEG 16 bit LinearRaw": (_frame(high=65536), dict(
        linear=True, tile=(32, 64), **LOSSLESS_JPEG)),
    "Deflate, predictor 2": (_frame(), dict(tile=(32, 32), compression="zlib", predictor=2)),
    "Deflate, predictor 2, strips": (_frame(), dict(rowsperstrip=20, compression="zlib",
                                                    predictor=2)),
    "float32 LinearRaw, Deflate, float predictor": (_frame(np.float32), dict(
        linear=True, tile=(32, 32), compression="zlib", predictor=3)),
    "float32 LinearRaw, Deflate strips, float predictor": (_frame(np.float32), dict(
        linear=True, rowsperstrip=16, compression="zlib", predictor=3)),
    "JPEG XL (DNG 1.7), lossless": (_frame(), dict(
        tile=(32, 64), compression="jpegxl_dng", compressionargs={"lossless": True})),
    "raw in a SubIFD, JPEG preview on top": (_frame(), dict(
        subifd=True, tile=(32, 32), **LOSSLESS_JPEG)),
    "BigTIFF": (_frame(), dict(bigtiff=True, tile=(32, 32), **LOSSLESS_JPEG)),
    "big-endian, Deflate, predictor 2": (_frame(), dict(byteorder=">", tile=(32, 32),
                                                        compression="zlib", predictor=2)),
    "big-endian float32, float predictor": (_frame(np.float32), dict(
        byteorder=">", linear=True, tile=(32, 32), compression="zlib", predictor=3)),
}


@pytest.mark.parametrize("name", LOSSLESS)
def test_lossless_variant_decodes_exactly(name, tmp_path):
    frame, options = LOSSLESS[name]
    path = tmp_path / "variant.dng"
    _write_dng(path, frame, **options)
    with tifffile.TiffFile(path) as tif:  # the variant really is what its name says
        page = _raw_page(tif)
        assert page.compression != 1 and page.shape == frame.shape
    result = _decode(path, tmp_path / "frames.tif")
    assert result.exit_code == 0, result.output + result.stderr
    decoded = tifffile.imread(tmp_path / "frames.tif")
    assert decoded.dtype == frame.dtype
    np.testing.assert_array_equal(decoded.reshape(frame.shape), frame)


@pytest.mark.parametrize("byteorder,coded", [
    (">", (32, 32)),      # big-endian: tifffile will not compress into one, so encoded here
    ("<", (32, 16, 2)),   # two components of half width, as Adobe's converter codes CFA tiles
    ("<", (16, 64)),      # half the rows, twice the width
])
def test_lossless_jpeg_tiles_coded_here_decode_exactly(byteorder, coded, tmp_path):
    """The DNG spec lets a lossless-JPEG tile be coded in any shape of the same sample count."""
    frame, tile = _frame(high=65536), 32
    padded = np.zeros((96, 128), np.uint16)
    padded[:ROWS, :COLS] = frame
    tiles = (imagecodecs.jpeg_encode(padded[r:r + tile, c:c + tile].reshape(coded),
                                     lossless=True, bitspersample=16)
             for r in range(0, ROWS, tile) for c in range(0, COLS, tile))
    _write_dng(tmp_path / "coded.dng", tiles, byteorder=byteorder, shape=frame.shape,
               dtype=np.uint16, tile=(tile, tile), compression=7, bitspersample=16)
    assert _decode(tmp_path / "coded.dng", tmp_path / "frames.tif").exit_code == 0
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "frames.tif"), frame)


def _smooth8() -> np.ndarray:
    rows, cols = np.mgrid[:ROWS, :COLS]
    return ((rows * 2 + cols) % 256).astype(np.uint8)


def test_lossy_jpeg_linear_raw_gives_what_the_file_holds(tmp_path):
    """A lossy DNG (8-bit LinearRaw, compression 34892): its pixels are the JPEG tiles'."""
    frame, tile = _smooth8(), 32
    path = tmp_path / "lossy.dng"
    _write_dng(path, frame, linear=True, white=255, tile=(tile, tile), compression="jpeg",
               compressionargs={"level": 90})
    _patch_raw_tag(path, 259, 34892)
    offsets, counts = _segments(path)
    data = path.read_bytes()
    held = np.zeros((96, 128), np.uint8)
    across = -(-COLS // tile)
    for k, (offset, count) in enumerate(zip(offsets, counts, strict=True)):
        r, c = divmod(k, across)
        held[r * tile:(r + 1) * tile, c * tile:(c + 1) * tile] = imagecodecs.jpeg8_decode(
            data[offset:offset + count])
    held = held[:ROWS, :COLS]
    assert not np.array_equal(held, frame)  # lossy indeed
    assert _decode(path, tmp_path / "frames.tif").exit_code == 0
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "frames.tif"), held)


def _halve_count(path, k=1):
    _patch_raw_tag(path, 325 if _is_tiled(path) else 279, _segments(path)[1][k] // 2, index=k)


def _is_tiled(path) -> bool:
    with tifffile.TiffFile(path) as tif:
        return _raw_page(tif).is_tiled


def _zero_count(path, k=1):
    _patch_raw_tag(path, 325 if _is_tiled(path) else 279, 0, index=k)


def _zero_tile(path, k=1):
    offsets, counts = _segments(path)
    data = bytearray(path.read_bytes())
    data[offsets[k]:offsets[k] + counts[k]] = bytes(counts[k])
    path.write_bytes(bytes(data))


def _offset_at_tile_0(path, k=1):
    _patch_raw_tag(path, 324 if _is_tiled(path) else 273, _segments(path)[0][0], index=k)


def _count_into_next(path, k=1):
    _patch_raw_tag(path, 325 if _is_tiled(path) else 279, _segments(path)[1][k] + 10, index=k)


DAMAGED = {  # name: (frame, write options, damage, words in the message)
    "lossless JPEG tile cut short": (_frame(), dict(tile=(32, 32), **LOSSLESS_JPEG),
                                     _halve_count, "JPEG tile 1 has no end-of-image marker"),
    "lossless JPEG strip cut short": (_frame(), dict(rowsperstrip=16, **LOSSLESS_JPEG),
                                      _halve_count, "JPEG strip 1 has no end-of-image marker"),
    "lossy JPEG tile cut short": (_smooth8(), dict(linear=True, white=255, tile=(32, 32),
                                                   compression="jpeg"),
                                  _halve_count, "JPEG tile 1 has no end-of-image marker"),
    "Deflate strip of no bytes": (_frame(), dict(rowsperstrip=16, compression="zlib"),
                                  _zero_count, "strip 1 has no data"),
    "JPEG samples wider than BitsPerSample": (
        _frame(high=65536), dict(tile=(32, 32), compression="jpeg",
                                 compressionargs={"lossless": True, "bitspersample": 16}),
        lambda p: _patch_raw_tag(p, 258, 8), "16-bit samples, the header says 8 bits"),
    "lossless JPEG tile zeroed": (_frame(), dict(tile=(32, 32), **LOSSLESS_JPEG), _zero_tile,
                                  "has no end-of-image marker"),
    "Deflate tile zeroed": (_frame(), dict(tile=(32, 32), compression="zlib", predictor=2),
                            _zero_tile, "raw IFD 0 is damaged"),
    "Deflate tile offset at tile 0": (_frame(), dict(tile=(32, 32), compression="zlib",
                                                     predictor=2),
                                      _offset_at_tile_0, "two tiles share the bytes"),
    "Deflate strip offset at strip 0": (_frame(), dict(rowsperstrip=16, compression="zlib"),
                                        _offset_at_tile_0, "two strips share the bytes"),
    "float Deflate byte count into the next tile": (
        _frame(np.float32), dict(linear=True, tile=(32, 32), compression="zlib", predictor=3),
        _count_into_next, "two tiles share the bytes"),
    "JPEG XL tile cut short": (_frame(), dict(tile=(32, 32), compression="jpegxl_dng",
                                              compressionargs={"lossless": True}),
                               _halve_count, "raw IFD 0 is damaged"),
}


@pytest.mark.parametrize("name", DAMAGED)
def test_damaged_variant_is_refused(name, tmp_path):
    frame, options, damage, words = DAMAGED[name]
    path = tmp_path / "damaged.dng"
    _write_dng(path, frame, **options)
    damage(path)
    _assert_refused(path, tmp_path, "damaged", words)


@pytest.mark.parametrize("samples,options", [
    (2, dict(planarconfig="separate")),
    (3, dict(planarconfig="contig", tile=(32, 32), **LOSSLESS_JPEG)),
])
def test_multi_sample_raw_is_refused(samples, options, tmp_path):
    frames = np.stack([_frame(seed=s) for s in range(samples)])
    data = frames if options["planarconfig"] == "separate" else np.moveaxis(frames, 0, -1)
    path = tmp_path / "samples.dng"
    _write_dng(path, data, linear=True, **options)  # tifffile refuses a multi-sample CFA page
    _patch_raw_tag(path, 262, 32803)
    _assert_refused(path, tmp_path, f"holds {samples} samples per pixel",
                    "one sample per pixel")


def test_cut_jpeg_strip_in_a_sensor_tiff_is_refused(tmp_path):
    """Plain sensor TIFFs (decode) and TIFFs read by the other stages: the same check."""
    path = tmp_path / "sensor.tif"
    tifffile.imwrite(path, _frame(), rowsperstrip=16, **LOSSLESS_JPEG)
    _halve_count(path)
    _assert_refused(path, tmp_path, "JPEG strip 1 has no end-of-image marker")
    with pytest.raises(InputError, match="JPEG strip 1 has no end-of-image marker"):
        tiffio.read_image(path)


@pytest.mark.parametrize("entries", [256, 100, 65536])
def test_linearization_table_maps_the_stored_codes(entries, tmp_path):
    """Lossy and some camera DNGs store codes: the frame is the table's levels (DNG spec), a
    code beyond the table taking its last entry."""
    codes = _frame(np.uint8, high=256)
    table = (np.arange(entries) ** 2 // 4 + 7).astype(np.uint16)
    _write_dng(tmp_path / "coded.dng", codes, white=16000, tile=(32, 32), **LOSSLESS_JPEG,
               extratags=[(50712, "H", entries, tuple(int(v) for v in table), True)])
    assert _decode(tmp_path / "coded.dng", tmp_path / "frames.tif").exit_code == 0
    truth = np.array([table[min(int(c), entries - 1)] for c in codes.ravel()], np.uint16)
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "frames.tif"),
                                  truth.reshape(codes.shape))


def test_float_raw_without_white_level_takes_the_dng_default(tmp_path):
    """audit 20 F2: refused as having 'no white level; give it with --white', and --white then
    refused for a raw: the DNG spec's default for floating-point samples is 1.0."""
    path = tmp_path / "float.dng"
    frame = _frame(np.float32) / np.float32(4000)
    _write_dng(path, frame, linear=True, white=None, tile=(32, 32), compression="zlib",
               predictor=3)
    got, meta = raw.decode(path)
    assert meta["white_level"] == [1.0] and np.array_equal(got[0], frame)


def _patch_raw_bytes(path: Path, code: int, values: bytes) -> None:
    with tifffile.TiffFile(path) as tif:
        offset = _raw_page(tif).tags[code].valueoffset
    data = bytearray(path.read_bytes())
    data[offset:offset + len(values)] = values
    path.write_bytes(bytes(data))


def _with_tags(*tags):
    return dict(tile=(32, 32), compression="zlib", extratags=list(tags))


def _float_with(value):
    frame = _frame(np.float32)
    frame[3, 4] = value
    return frame


LYING_HEADERS = {  # name: (frame, write options, damage or None, words in the message)
    "tiles of 65536 x 65536": (_frame(), dict(tile=(32, 32), **LOSSLESS_JPEG),
                               lambda p: (_patch_raw_tag(p, 322, 65536),
                                          _patch_raw_tag(p, 323, 65536)), "tiles of 65536"),
    "JPEG tiles coded at another size": (_frame(), dict(tile=(32, 32), **LOSSLESS_JPEG),
                                         lambda p: _patch_raw_tag(p, 322, 33),
                                         "codes 1024 samples"),
    "tiles of another width, as many": (_frame(), dict(tile=(32, 32), compression="zlib"),
                                        lambda p: _patch_raw_tag(p, 322, 33),
                                        "decodes to 2048 bytes"),
    "image width that needs fewer tiles": (_frame(), dict(tile=(32, 32), compression="zlib"),
                                           lambda p: _patch_raw_tag(p, 256, 1), "12 tiles"),
    "strip width changed": (_frame(), dict(rowsperstrip=16, compression="zlib"),
                            lambda p: _patch_raw_tag(p, 256, 93), "decodes to"),
    "strip in the header": (_frame(), {}, lambda p: _patch_raw_tag(p, 273, 2),
                            "lies in the file's header"),
    "tile length 0": (_frame(), dict(tile=(32, 32), compression="zlib"),
                      lambda p: _patch_raw_tag(p, 323, 0), "tile size of 32 x 0"),
    "CFAPattern colour 5 (yellow)": (_frame(), {}, lambda p: _patch_raw_bytes(
        p, 33422, bytes([0, 5, 1, 2])), "CFAPattern [0, 5, 1, 2]"),
    "CFAPattern colour 3 (cyan)": (_frame(), {}, lambda p: _patch_raw_bytes(
        p, 33422, bytes([0, 3, 1, 2])), "other than red, green or blue"),
    "CFAPattern not Bayer": (_frame(), {}, lambda p: _patch_raw_bytes(
        p, 33422, bytes([0, 0, 1, 2])), "RRGB is not a Bayer"),
    "CFA repeat 0 x 0": (_frame(), {}, lambda p: (_patch_raw_tag(p, 33421, 0, 0),
                                                  _patch_raw_tag(p, 33421, 0, 1)),
                         "CFARepeatPatternDim 0 x 0"),
    "CFA repeat 6 x 6 (X-Trans)": (_frame(), {}, lambda p: (_patch_raw_tag(p, 33421, 6, 0),
                                                            _patch_raw_tag(p, 33421, 6, 1)),
                                   "CFARepeatPatternDim 6 x 6"),
    "BlackLevel 0/0": (_frame(), _with_tags((50714, "2I", 1, (0, 0), True)), None,
                       "BlackLevel holds 0/0"),
    "BlackLevel repeat 3 x 3": (_frame(), _with_tags((50713, "H", 2, (3, 3), True),
                                                     (50714, "H", 9, (10,) * 9, True)), None,
                                "BlackLevelRepeatDim [3, 3]"),
    "BlackLevel count short of its repeat": (_frame(), _with_tags(
        (50713, "H", 2, (2, 2), True), (50714, "H", 2, (10, 10), True)), None,
        "BlackLevel has 2 values"),
    "BlackLevelDeltaH not applied": (_frame(), _with_tags(
        (50715, "d", COLS, (100.0,) * COLS, True)), None, "BlackLevelDeltaH"),
    "WhiteLevel beyond the samples": (_frame(), dict(white=10 ** 9), None, "WhiteLevel"),
    "LinearizationTable of LONG levels past 16 bits": (
        _frame(np.uint8, high=256), _with_tags((50712, "I", 256, tuple(range(0, 256000, 1000)),
                                                True)), None, "LinearizationTable"),
    "LinearizationTable of doubles": (
        _frame(np.uint8, high=256), _with_tags((50712, "d", 4, (1.0, 2.0, 3.0, 4.0), True)),
        None, "LinearizationTable"),
    "uncompressed 16-bit samples labelled 12-bit": (_frame(), {},
                                                   lambda p: _patch_raw_tag(p, 258, 12),
                                                   "12 bits per sample"),
    "MaskedAreas reaching into ActiveArea": (_frame(), _with_tags(
        (50829, "I", 4, (0, 8, ROWS, COLS), True), (50830, "I", 4, (0, 0, ROWS, 12), True)),
        None, "MaskedAreas [0, 0, 75, 12] overlaps ActiveArea"),
    "ActiveArea covering MaskedAreas": (_frame(), _with_tags(
        (50829, "I", 4, (0, 0, ROWS, COLS), True), (50830, "I", 4, (0, 0, ROWS, 8), True)),
        None, "overlaps ActiveArea"),
    # audit 21 M1: named by the tag, not told to "decode the capture again"
    "ActiveArea beyond the image": (_frame(), _with_tags(
        (50829, "I", 4, (4, 8, ROWS + 6, COLS), True)), None,
        f"ActiveArea [4, 8, {ROWS + 6}, {COLS}] is not a [top, left, bottom, right] rectangle "
        f"inside the {COLS} x {ROWS} raw image; the DNG is damaged"),
    "MaskedAreas empty": (_frame(), _with_tags((50829, "I", 4, (0, 8, ROWS, COLS), True),
                                               (50830, "I", 4, (0, 0, 0, 8), True)),
                          None, "MaskedAreas [0, 0, 0, 8] is not a [top, left, bottom, right]"),
    # audit 24 W2: developed as stored (squashed), where LibRaw stretches by pixel aspect
    "DefaultScale 2 x 1 (pixels not square)": (_frame(), _with_tags(
        (50718, "2I", 2, (2, 1, 1, 1), True)), None, "DefaultScale 2 x 1: its pixels are not "
                                                     "square"),
    "DefaultScale 0 x 1": (_frame(), _with_tags((50718, "2I", 2, (0, 1, 1, 1), True)), None,
                           "DefaultScale [0.0, 1.0] is not two positive numbers"),
    "DefaultScale 1.5 x 1": (_frame(), _with_tags((50718, "2I", 2, (3, 2, 1, 1), True)), None,
                             "DefaultScale 1.5 x 1"),
    "float samples NaN": (_float_with(np.nan), dict(linear=True, white=1, tile=(32, 32),
                                                    compression="zlib", predictor=3),
                          None, "1 NaN or infinite samples"),
    "float samples Inf": (_float_with(-np.inf), dict(linear=True, white=1, tile=(32, 32),
                                                     compression="zlib", predictor=3),
                          None, "1 NaN or infinite samples"),
}


@pytest.mark.parametrize("compression,code", [("lzw", 5), ("packbits", 32773), ("zstd", 50000),
                                              ("ccitt_rle", 2)])
def test_a_compression_dng_does_not_allow_is_named(compression, code, tmp_path):
    """DNG allows Compression 1, 7, 8, 34892 and 52546 for raw data; another one (LZW decoded,
    CCITT on 16-bit samples gave 0/1 or zeros, exit 0) is refused naming the tag (audit 19 W2)."""
    path = tmp_path / "other.dng"
    _write_dng(path, _frame(), rowsperstrip=16,
               compression=None if code == 2 else compression)
    if code == 2:  # tifffile writes no CCITT: the tag of an uncompressed file changed
        _patch_raw_tag(path, 259, code)
    _assert_refused(path, tmp_path, f"Compression {code}")


@pytest.mark.parametrize("name", LYING_HEADERS)
def test_a_header_field_that_breaks_the_rules_is_named(name, tmp_path):
    frame, options, damage, words = LYING_HEADERS[name]
    path = tmp_path / "lying.dng"
    _write_dng(path, frame, **options)
    if damage is not None:
        damage(path)
    _assert_refused(path, tmp_path, words)


def test_rational_black_levels_over_a_2x2_repeat_are_divided_out(tmp_path):
    """DNG converters write BlackLevel as RATIONALs: four levels, not numerator/denominator
    pairs taken for levels."""
    levels = (1024, 1025, 1026.5, 1027)
    rationals = tuple(v for level in levels for v in (int(level * 2), 2))
    path = tmp_path / "black.dng"
    _write_dng(path, _frame(), **_with_tags((50713, "H", 2, (2, 2), True),
                                            (50714, "2I", 4, rationals, True)))
    assert _decode(path, tmp_path / "frames.tif").exit_code == 0
    assert tiffio.read_meta(tmp_path / "frames.tif")["black_level"] == [list(levels)]


def test_packed_12_bit_uncompressed_raw_decodes_exactly(tmp_path):
    """Uncompressed 12-bit raws pack two samples in three bytes; the byte count checks
    account for it."""
    frame = _frame(high=4096)
    path = tmp_path / "packed.dng"
    _write_dng(path, np.zeros_like(frame), white=4095, rowsperstrip=ROWS)
    packed = bytearray()
    for row in frame.astype(np.uint32):
        bits = "".join(f"{v:012b}" for v in row) + "0" * (-12 * COLS % 8)
        packed += int(bits, 2).to_bytes(len(bits) // 8, "big")
    offset = _segments(path)[0][0]
    data = bytearray(path.read_bytes())
    data[offset:offset + len(packed)] = packed
    path.write_bytes(bytes(data[:offset + len(packed)]) + bytes(data[offset + ROWS * COLS * 2:]))
    _patch_raw_tag(path, 258, 12)
    _patch_raw_tag(path, 279, len(packed))
    result = _decode(path, tmp_path / "frames.tif")
    assert result.exit_code == 0, result.stderr
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "frames.tif"), frame)


def test_frames_of_another_cfa_or_area_are_not_stacked(tmp_path):
    """Every raw IFD's layout is read: frame 1 with another CFA phase would be processed with
    frame 0's."""
    from plenocli.io.dng import write_dng

    path = tmp_path / "two.dng"
    frames = np.stack([_frame(), _frame(seed=1)])
    write_dng(path, frames, cfa="RGGB", black_levels=[0, 0], white_level=16383,
              active_area=[0, 0, ROWS, COLS])
    with tifffile.TiffFile(path) as tif:
        offset = tif.pages[1].tags[33422].valueoffset
    data = bytearray(path.read_bytes())
    data[offset:offset + 4] = bytes([1, 0, 2, 1])  # GRBG
    path.write_bytes(bytes(data))
    _assert_refused(path, tmp_path, "raw IFD 1 has another CFA pattern")


def _two_frames(path: Path) -> None:
    from plenocli.io.dng import write_dng

    write_dng(path, np.stack([_frame(), _frame(seed=1)]), cfa="RGGB", black_levels=[0, 0],
              white_level=16383, active_area=[0, 0, ROWS, COLS])


def _patch_page_tag(path: Path, page: int, code: int, value: int) -> None:
    with tifffile.TiffFile(path) as tif:
        tag = tif.pages[page].tags[code]
        fmt = tif.byteorder + {3: "H", 4: "I"}[int(tag.dtype)]
        offset = tag.valueoffset
    data = bytearray(path.read_bytes())
    data[offset:offset + struct.calcsize(fmt)] = struct.pack(fmt, value)
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("page,code,value,words", [
    (0, 262, 1, "IFD 0 has NewSubFileType 0 and Photometric 1"),   # main image, not raw
    (0, 254, 1, "raw of full size flagged as a reduced preview"),
    (1, 254, 0xFFFFFFFF, "NewSubFileType 4294967295"),
])
def test_a_frame_dropped_by_its_ifd_flags_is_refused(page, code, value, words, tmp_path):
    """Two frames whose header damage would silently give one."""
    path = tmp_path / "two.dng"
    _two_frames(path)
    _patch_page_tag(path, page, code, value)
    _assert_refused(path, tmp_path, words)


def test_frames_that_share_bytes_are_refused(tmp_path):
    path = tmp_path / "two.dng"
    _two_frames(path)
    with tifffile.TiffFile(path) as tif:
        start = int(tif.pages[0].dataoffsets[0])
    _patch_page_tag(path, 0, 273, start + 4)  # frame 0 read 4 bytes late: into frame 1
    _assert_refused(path, tmp_path, "share the bytes")


@pytest.mark.parametrize("top,left,at_origin", [(0, 0, "RGGB"), (1, 0, "GBRG"), (0, 1, "GRBG"),
                                                (1, 1, "BGGR")])
def test_cfa_pattern_and_black_repeat_start_at_the_active_area(top, left, at_origin, tmp_path):
    """DNG gives CFAPattern and the BlackLevel repeat at the ActiveArea's top-left (as the DNG
    SDK, LibRaw and rawspeed read them): an active area from an odd row or column shifts both
    on the stored frame (audit 15: red and blue were swapped, exit 0)."""
    path = tmp_path / "odd.dng"
    black = (50713, "H", 2, (2, 2), True), (50714, "H", 4, (10, 20, 30, 40), True)
    _write_dng(path, _frame(), extratags=[(50829, "I", 4, (top, left, ROWS, COLS), True), *black])
    assert _decode(path, tmp_path / "frames.tif").exit_code == 0
    meta = tiffio.read_meta(tmp_path / "frames.tif")
    assert meta["cfa"] == at_origin
    grid = np.array([[10, 20], [30, 40]])
    assert meta["black_level"][0] == [grid[(r - top) % 2, (c - left) % 2]
                                      for r in (0, 1) for c in (0, 1)]


def test_written_dng_keeps_the_pattern_of_its_frames(tmp_path):
    """plenocli's own DNGs (simulate) round-trip with an active area from an odd row and
    column, and LibRaw reads the colour plenocli meant at the active area's corner."""
    from plenocli.io.dng import write_dng
    frame = _frame()
    path = tmp_path / "sim.dng"
    write_dng(path, frame, cfa="RGGB", black_levels=[0.0], white_level=16383,
              active_area=[1, 1, ROWS, COLS - 2])
    assert _decode(path, tmp_path / "frames.tif").exit_code == 0
    assert tiffio.read_meta(tmp_path / "frames.tif")["cfa"] == "RGGB"
    import rawpy
    with rawpy.imread(str(path)) as raw:
        assert "RGBG"[raw.raw_color(1, 1)] == "B"  # RGGB at (0, 0): blue at (1, 1)


def test_square_pixels_shown_larger_decode_as_stored(tmp_path):
    """DefaultScale 1.5 x 1.5 scales the picture shown, its pixels square (audit 25: refused
    as 'not square')."""
    frame = _frame()
    _write_dng(tmp_path / "big.dng", frame, extratags=[(50718, "2I", 2, (3, 2, 3, 2), True)])
    _write_dng(tmp_path / "plain.dng", frame)
    np.testing.assert_array_equal(raw.decode(tmp_path / "big.dng")[0],
                                  raw.decode(tmp_path / "plain.dng")[0])


def test_an_enhanced_image_beside_the_raw_is_not_read(tmp_path):
    """audit 24 F3: a DNG 1.5 enhanced image (NewSubFileType 16, a demosaiced LinearRaw, as
    Adobe's Enhance writes it) beside the raw was called damage; it is skipped as a preview is,
    and the raw decodes as without it."""
    frame = _frame()
    _write_dng(tmp_path / "plain.dng", frame)
    tags = _dng_tags(cfa=True, white=65535)
    with tifffile.TiffWriter(tmp_path / "enhanced.dng") as writer:
        writer.write(frame, photometric=32803, subfiletype=0, metadata=None, extratags=tags)
        writer.write(np.full((*frame.shape, 3), 1000, np.uint16), subfiletype=16,
                     photometric=34892, metadata=None)
    plain, _ = raw.decode(tmp_path / "plain.dng")
    enhanced, _ = raw.decode(tmp_path / "enhanced.dng")
    np.testing.assert_array_equal(enhanced, plain)


def test_an_as_shot_white_given_as_xy_is_said_not_read(tmp_path):
    """audit 24 F4: a DNG whose as-shot white is AsShotWhiteXY (no AsShotNeutral) decoded
    without a word, and develop then said the file had no as-shot white."""
    from tests.logs import plenocli_messages

    _write_dng(tmp_path / "xy.dng", _frame(),
               extratags=[(50729, "2I", 2, (3127, 10000, 3290, 10000), True)])
    with plenocli_messages() as said:
        _, meta = raw.decode(tmp_path / "xy.dng")
    assert meta["colour"]["as_shot_wb"] is None
    assert any("AsShotWhiteXY, which plenocli does not read" in m for m in said), said
