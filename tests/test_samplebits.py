"""A light level is one rule in every format (audit 21 W1): the white of samples that carry
fewer bits than their word is 2^bits - 1, as a PNG's sBIT or a BMP's bit masks declare it
(the 12-bit PNG's white was 65535 and its clipped pixels at 4095 were kept as light)."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest
import tifffile

from plenocli.errors import InputError
from plenocli.io import raw

# a 12-bit ramp with 8 clipped pixels (at 4095)
TWELVE = (np.arange(64 * 80).reshape(64, 80) % 4001).astype(np.uint16)
TWELVE[0, :8] = 4095


def _chunk(kind: bytes, body: bytes) -> bytes:
    return (struct.pack(">I", len(body)) + kind + body
            + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))


def _png(path, samples: np.ndarray, sbit: list[int], depth: int = 16,
         colour: int | None = None, before: bytes = b"") -> None:
    """A grey (rows, cols) or RGB (rows, cols, 3) PNG (``colour``: another IHDR colour type for
    those samples) with an sBIT chunk after the chunks ``before``, written by hand."""
    colour = (0 if samples.ndim == 2 else 2) if colour is None else colour
    rows, cols = samples.shape[:2]
    word = ">u2" if depth == 16 else "u1"
    body = b"".join(b"\x00" + samples[r].astype(word).tobytes() for r in range(rows))
    path.write_bytes(b"\x89PNG\r\n\x1a\n"
                     + _chunk(b"IHDR", struct.pack(">IIBBBBB", cols, rows, depth, colour, 0, 0, 0))
                     + before + _chunk(b"sBIT", bytes(sbit))
                     + _chunk(b"IDAT", zlib.compress(body))
                     + _chunk(b"IEND", b""))


def _bmp(path, bpp: int, masks: tuple[int, int, int], words: np.ndarray) -> None:
    """A BI_BITFIELDS BMP of (rows, cols) pixel words, its masks after a 40-byte header."""
    rows, cols = words.shape
    stride = (cols * bpp // 8 + 3) // 4 * 4
    pixels = b"".join(words[r].astype(f"<u{bpp // 8}").tobytes().ljust(stride, b"\0")
                      for r in range(rows - 1, -1, -1))
    offset = 14 + 40 + 12
    path.write_bytes(b"BM" + struct.pack("<IHHI", offset + len(pixels), 0, 0, offset)
                     + struct.pack("<IiiHHIIiiII", 40, cols, rows, 1, bpp, 3, len(pixels), 2835,
                                   2835, 0, 0) + struct.pack("<III", *masks) + pixels)


def test_a_12_bit_png_reads_as_the_12_bit_tiff_however_it_stores_its_bits(tmp_path):
    """Stored as they are (0-4095), shifted up, or scaled to 0-65535 as the PNG standard has
    it: the frame and white of the 12-bit TIFF of the same samples (4095), so the clipped
    pixels are the TIFF's."""
    tifffile.imwrite(tmp_path / "t.tif", TWELVE, bitspersample=12)
    linear = np.floor(TWELVE * (65535 / 4095) + 0.5).astype(np.uint16)
    for name, stored in (("as_is", TWELVE), ("shifted", TWELVE << 4), ("scaled", linear)):
        _png(tmp_path / f"{name}.png", stored, [12])
    want, meta = raw.decode(tmp_path / "t.tif")
    assert meta["white_level"] == [4095.0]
    for name in ("as_is", "shifted", "scaled"):
        frames, meta = raw.decode(tmp_path / f"{name}.png")
        assert meta["white_level"] == [4095.0], name
        assert np.array_equal(frames, want), name
    with pytest.raises(InputError, match=r"beyond what its 12-bit samples \(PNG sBIT 12\) can "
                                         r"reach \(4095\)"):
        raw.decode(tmp_path / "as_is.png", white=5000)


def test_a_png_whose_samples_contradict_its_sbit_is_refused(tmp_path):
    """Samples past 12 bits that no scaling of 12-bit values writes: header and image disagree."""
    odd = TWELVE.copy()
    odd[5, 5] = 40001
    _png(tmp_path / "odd.png", odd, [12])
    with pytest.raises(InputError, match="neither 12-bit values nor such values scaled"):
        raw.decode(tmp_path / "odd.png")
    _png(tmp_path / "wide.png", TWELVE, [17])
    with pytest.raises(InputError, match="declares 17 significant bits for 16-bit samples"):
        raw.decode(tmp_path / "wide.png")


def test_an_rgb_png_takes_each_channels_bits(tmp_path):
    """sBIT 5, 6, 5 on an 8-bit RGB scaled by bit replication: whites 31, 63, 31 (as a TIFF's
    per-sample MaxSampleValue gives one white a frame), the 5/6-bit samples recovered."""
    rng = np.random.default_rng(1)
    five = rng.integers(0, 32, (20, 30, 3))
    five[..., 1] = rng.integers(0, 64, (20, 30))
    five[0, 0] = (31, 63, 31)
    bits = np.array([5, 6, 5])
    stored = (five << (8 - bits)) | (five >> (2 * bits - 8))
    _png(tmp_path / "rgb.png", stored.astype(np.uint8), [5, 6, 5], depth=8)
    frames, meta = raw.decode(tmp_path / "rgb.png")
    assert meta["white_level"] == [31.0, 63.0, 31.0]
    assert np.array_equal(frames, np.moveaxis(five, -1, 0))


def test_bmp_of_16_bit_or_masked_pixels_is_refused(tmp_path):
    """5-6-5 and 10-10-10 BMPs: OpenCV read 5-bit samples shifted into bytes (white 248 under
    a white of 255) and a 10-10-10 BMP's words as bytes (wrong colours, exit 0)."""
    rng = np.random.default_rng(2)
    r, g, b = rng.integers(0, 32, (3, 12, 10))
    _bmp(tmp_path / "565.bmp", 16, (0xF800, 0x7E0, 0x1F), (r << 11) | (g << 5) | b)
    with pytest.raises(InputError, match="BMP of 16-bit pixels"):
        raw.decode(tmp_path / "565.bmp")
    ten = rng.integers(0, 1024, (3, 12, 10))
    _bmp(tmp_path / "10.bmp", 32, (0x3FF00000, 0xFFC00, 0x3FF),
         (ten[0] << 20) | (ten[1] << 10) | ten[2])
    with pytest.raises(InputError, match="pixels given by bit masks"):
        raw.decode(tmp_path / "10.bmp")
    plain = rng.integers(0, 256, (12, 10))
    _bmp(tmp_path / "888.bmp", 32, (0xFF0000, 0xFF00, 0xFF), (plain << 16) | (plain << 8) | plain)
    frames, meta = raw.decode(tmp_path / "888.bmp")   # audit 23 F1: the plain layout is read
    assert np.array_equal(frames[0], plain)


def test_grey_alpha_png_of_16_bits_is_its_grey_and_an_sbit_after_the_palette_is_refused(
        tmp_path):
    """Audit 23 W2/W3: Pillow calls a 16-bit grey + alpha PNG "RGBA", so it was read as R, G, B
    pages of white 65535 (its sBIT 12 dropped); an sBIT after the palette (libpng ignores it)
    left a grey-palette PNG at white 255 where its grey PNG has 63."""
    grey = np.random.default_rng(4).integers(0, 4096, (8, 6))
    alpha = np.full_like(grey, 65535)
    _png(tmp_path / "ga.png", np.stack([grey, alpha], -1), [12, 16], colour=4)
    frames, meta = raw.decode(tmp_path / "ga.png")
    assert frames.shape == (1, 8, 6) and meta["white_level"] == [4095.0]
    assert np.array_equal(frames[0], grey)
    table = _chunk(b"PLTE", bytes(i // 3 for i in range(3 * 256)))
    _png(tmp_path / "late.png", grey % 64, [6, 6, 6], depth=8, colour=3, before=table)
    with pytest.raises(InputError, match="sBIT chunk comes after its palette"):
        raw.decode(tmp_path / "late.png")
