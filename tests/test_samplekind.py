"""One rule for what is a light level, in every image format (audit 18 P1), and messages that
say what is wrong with a file in plain words, not Python's (audit 18 M1)."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import tifffile
from PIL import Image

from plenocli.colour import balance
from plenocli.errors import InputError, library_words, numbers, plain_words
from plenocli.io import raw
from plenocli.pipeline.stages.calibrate import load_image
from plenocli.pipeline.stages.flat import _masked_words

GREY = (np.arange(60 * 80).reshape(60, 80) % 251).astype(np.uint8)


def _palette_image(table: np.ndarray) -> Image.Image:
    """GREY stored as indices into ``table`` (256, 3): each grey's index is where it sits."""
    order = np.random.default_rng(0).permutation(256)
    index = np.argsort(order).astype(np.uint8)
    image = Image.fromarray(index[GREY], "P")
    image.putpalette(table[order].ravel().tolist())
    return image


def _colour_bmp(path):
    """An 8-bit BMP whose table holds colours (index i -> 255-i, i, 7i), written by hand."""
    rows, cols = GREY.shape
    offset, pixels = 14 + 40 + 1024, GREY[::-1].tobytes()
    table = b"".join(bytes([(7 * i) % 256, i, 255 - i, 0]) for i in range(256))
    path.write_bytes(b"BM" + struct.pack("<IHHI", offset + len(pixels), 0, 0, offset)
                     + struct.pack("<IiiHHIIiiII", 40, cols, rows, 1, 8, 0, len(pixels), 2835,
                                   2835, 256, 0) + table + pixels)


def test_a_grey_image_reads_the_same_in_every_format_and_storage(tmp_path):
    """Grey samples, a grey table (identity or any order), a TIFF named .png: one frame, equal
    to the grey image, whatever the format (the palette PNG was refused, a grey-table TIFF
    too, while a BMP's table was read)."""
    grey_table = np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, axis=1)
    Image.fromarray(GREY).save(tmp_path / "g.png")
    Image.fromarray(GREY).save(tmp_path / "g.bmp")
    Image.fromarray(GREY).convert("LA").save(tmp_path / "la.png")
    Image.fromarray(GREY).convert("P").save(tmp_path / "identity.png")
    tifffile.imwrite(tmp_path / "g.tif", GREY, photometric="minisblack")
    Image.fromarray(GREY).convert("P").save(tmp_path / "identity.tif")
    for suffix in ("png", "bmp", "tif"):
        _palette_image(grey_table).save(tmp_path / f"shuffled.{suffix}")
    (tmp_path / "tiff_named.png").write_bytes((tmp_path / "identity.tif").read_bytes())
    for path in sorted(tmp_path.iterdir()):
        frames, meta = raw.decode(path)
        assert frames.shape == (1, *GREY.shape) and meta["views"] == ["raw"], path.name
        assert np.array_equal(frames[0], GREY), path.name
        assert np.array_equal(load_image(str(path))[0], GREY), path.name


@pytest.mark.parametrize("suffix", ["png", "bmp", "tif"])
def test_a_colour_palette_and_a_one_bit_image_are_refused_in_every_format(tmp_path, suffix):
    """A colour BMP was read as three frames of its table's colours, a 1-bit PNG as 0/255,
    while the same TIFFs were refused: every format now refuses both, with the same words."""
    colours = np.stack([255 - np.arange(256), np.arange(256), 7 * np.arange(256) % 256], 1)
    _palette_image(colours.astype(np.uint8)).save(tmp_path / f"colour.{suffix}")
    if suffix == "bmp":
        _colour_bmp(tmp_path / "colour.bmp")
    Image.fromarray(GREY > 100).save(tmp_path / f"bilevel.{suffix}")
    for name, words in (("colour", "colour-palette"), ("bilevel", "1-bit (two-level)")):
        for read in (raw.decode, load_image):
            with pytest.raises(InputError, match="holds no light levels") as err:
                read(str(tmp_path / f"{name}.{suffix}"))
            assert words in str(err.value) and "\n" not in str(err.value)


def test_library_errors_are_said_in_plain_words(tmp_path):
    """'index 0 out of range(0)', 'raised error('unpack requires a buffer of 4 bytes')',
    b'...' and np.float64(...) were shown as they were."""
    assert library_words(IndexError("index 0 out of range(0)")) == (
        "a table is shorter than its header says")
    assert plain_words("invalid offset to page 2 @10 raised error('unpack requires a buffer "
                       "of 4 bytes')") == ("invalid offset to page 2 at byte 10: it ends "
                                           "inside a header or table")
    assert library_words(RuntimeError(b"Unsupported file format or not RAW file")) == (
        "Unsupported file format or not RAW file")
    assert numbers([np.float64(0.0), np.float64(900.0), 0.25]) == "0, 900, 0.25"
    for head in (b"II*\x00\x00\x00\x00\x00", b"II*\x00\x08\x00\x00\x00\x00\x00",
                 b"II*\x00\x08\x00\x00\x00CR\x02\x00" + bytes(64)):
        (tmp_path / "cut.tif").write_bytes(head)
        with pytest.raises(InputError) as err:
            raw.decode(tmp_path / "cut.tif")
        said = str(err.value)
        assert not any(w in said for w in ("range(", "unpack", "b'", "@", "raised")), said


def test_a_white_without_red_and_nan_in_a_white_are_said_as_such():
    mosaic = np.full((8, 8), 900.0)
    mosaic[0::2, 0::2] = 0.0   # RGGB: the red sites at black
    with pytest.raises(ValueError, match=r"the white's red sites average 0 \(at or below "
                                         r"black\)") as err:
        balance.gains_from_mosaic(mosaic, "RGGB", centre_fraction=1)
    assert "np." not in str(err.value)
    # audit 24 W3: red 2 DN above black gave a gain of 3744 (a red photograph, exit 0); a gain
    # measured past --wb's 100 : 1 is refused as --wb 3744,1,1 is, 100 : 1 itself is taken
    mosaic[0::2, 0::2] = 2.0
    with pytest.raises(ValueError, match=r"the white's red sites average 2, under 1/100 of its "
                                         r"green \(900\)"):
        balance.gains_from_mosaic(mosaic, "RGGB", centre_fraction=1)
    mosaic[0::2, 0::2] = 9.0
    assert balance.gains_from_mosaic(mosaic, "RGGB", centre_fraction=1)[0] == 100
    white = np.ones((1, 10, 10), np.float32)
    white[0, :2, :3] = np.nan
    gains = white.copy()
    gains[0, 9, 9] = np.nan
    assert _masked_words(7, white, gains) == (
        "7 pixels masked: 6 NaN in the white, 1 below the floor")


@pytest.mark.parametrize("suffix", ["png", "bmp"])
def test_a_pixel_past_its_palette_is_refused(tmp_path, suffix):
    """audit 20 W3: indices 8-15 over an 8-entry grey table were read as black light."""
    image = Image.fromarray((np.arange(20 * 30).reshape(20, 30) % 16).astype(np.uint8), "P")
    image.putpalette([v for i in range(8) for v in (17 * i,) * 3])
    image.save(tmp_path / f"short.{suffix}")
    with pytest.raises(InputError, match="index 15, past its 8-entry table"):
        raw.decode(tmp_path / f"short.{suffix}")
