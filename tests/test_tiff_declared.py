"""What a plain TIFF's header declares decides how it is read (audit 19 W1, W2, W5, W6, F1,
M1, M2): the white level of its BitsPerSample or MaxSampleValue, a compression that fits its
samples, a raw it declares by Photometric CFA, a grey page beside its alpha, text tags as
text, and refusals in plain words."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import tifffile
from PIL import Image

from plenocli.errors import InputError, plain_words
from plenocli.io import raw, rawmeta
from plenocli.io.dng import write_dng

GREY = (np.arange(60 * 80).reshape(60, 80) % 251).astype(np.uint8)


def _patch(path, code: int, value: int) -> None:
    """Set IFD 0's count-1 SHORT tag ``code`` of a little-endian TIFF to ``value``, in place."""
    data = bytearray(path.read_bytes())
    ifd = struct.unpack_from("<I", data, 4)[0]
    for k in range(struct.unpack_from("<H", data, ifd)[0]):
        entry = ifd + 2 + 12 * k
        if struct.unpack_from("<H", data, entry)[0] == code:
            struct.pack_into("<H", data, entry + 8, value)
            path.write_bytes(bytes(data))
            return
    raise AssertionError(f"no tag {code}")


@pytest.mark.parametrize("bits", [10, 12, 14])
def test_white_of_a_tiff_is_its_bits_and_white_beyond_them_is_refused(tmp_path, bits):
    """A 12-bit TIFF got white 65535 (saturated 4095s kept as light) and --white 5000 taken."""
    top = 2 ** bits - 1
    frame = np.random.default_rng(1).integers(0, top + 1, (64, 96)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "c.tif", frame, bitspersample=bits, photometric="minisblack")
    got, meta = raw.decode(tmp_path / "c.tif", cfa="RGGB")
    assert np.array_equal(got[0], frame) and meta["white_level"] == [float(top)]
    assert "sample_top" not in meta
    with pytest.raises(InputError, match=f"its {bits}-bit samples can reach \\({top}\\)"):
        raw.decode(tmp_path / "c.tif", white=top + 1)
    assert raw.decode(tmp_path / "c.tif", white=top - 10)[1]["white_level"] == [top - 10.0]


@pytest.mark.parametrize("dtype", [np.int16, np.int32])
def test_the_white_of_signed_samples_is_the_largest_they_hold(tmp_path, dtype):
    """audit 20 W1: int16 samples got white 65535 (2^16 - 1), which they cannot reach: their
    clipped 32767s passed as light and bias called decode's own output damaged."""
    frame = np.full((40, 50), 1000, dtype)
    frame[3:6, 4:8] = np.iinfo(dtype).max
    tifffile.imwrite(tmp_path / "s.tif", frame, photometric="minisblack")
    assert raw.decode(tmp_path / "s.tif")[1]["white_level"] == [float(np.iinfo(dtype).max)]


@pytest.mark.parametrize("dtype", [np.uint64, np.int64, np.uint32, np.int32])
def test_the_white_of_wide_samples_survives_decode_bias_and_flat(tmp_path, dtype):
    """audit 20 W1: decode recorded a uint64 TIFF's white 2^64 - 1 as the float 2^64 (int64:
    2^63) and bias refused decode's own output as 'edited or damaged'. The white is compared
    as it is stored, and the clipped samples still read as clipped at every stage."""
    from click.testing import CliRunner

    from plenocli.cli.main import cli
    from plenocli.io.tiffio import read_image

    frame = (np.arange(40 * 50).reshape(40, 50) % 3000 + 1000).astype(dtype)
    frame[3:6, 4:8] = np.iinfo(dtype).max
    tifffile.imwrite(tmp_path / "s.tif", frame, photometric="minisblack")
    tifffile.imwrite(tmp_path / "w.tif", np.full((40, 50), 20000, dtype), photometric="minisblack")
    for name in ("s", "w"):
        for args in (["decode", f"{name}.tif", "--cfa", "RGGB", "--black", "100",
                      "-o", f"d{name}.tif"],
                     ["bias", f"d{name}.tif", "--overscan", "none", "-o", f"b{name}.tif"]):
            done = CliRunner().invoke(cli, [str(tmp_path / a) if a.endswith(".tif") else a
                                            for a in args])
            assert done.exit_code == 0, done.output
    done = CliRunner().invoke(cli, ["flat", str(tmp_path / "bs.tif"), "--white",
                                    str(tmp_path / "bw.tif"), "-o", str(tmp_path / "f.tif")])
    assert done.exit_code == 0, done.output
    for out in ("bs.tif", "f.tif"):
        data = read_image(tmp_path / out)[0][0]
        assert np.isnan(data).sum() == 12  # the clipped samples, and only they
    biased = read_image(tmp_path / "bs.tif")[0][0]
    np.testing.assert_array_equal(biased[10:], frame[10:].astype(np.float64) - 100)


def test_a_white_beyond_32_bit_samples_is_refused_in_all_its_digits(tmp_path):
    """audit 20 M2's class: 'white level 4.29497e+09 is beyond what its uint32 samples can
    reach (4.29497e+09)' contradicted itself."""
    tifffile.imwrite(tmp_path / "u.tif", np.full((8, 8), 7, np.uint32), photometric="minisblack")
    with pytest.raises(InputError, match=r"white level 4294967296 .*can reach \(4294967295\)"):
        raw.decode(tmp_path / "u.tif", white=2.0 ** 32)


def test_max_sample_value_is_the_white_and_samples_past_it_are_refused(tmp_path):
    frame = np.random.default_rng(2).integers(0, 16384, (40, 50)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "m.tif", frame, photometric="minisblack",
                     extratags=[(281, "H", 1, 16383, True)])
    assert raw.decode(tmp_path / "m.tif")[1]["white_level"] == [16383.0]
    frame[3, 4] = 20000
    tifffile.imwrite(tmp_path / "past.tif", frame, photometric="minisblack",
                     extratags=[(281, "H", 1, 16383, True)])
    with pytest.raises(InputError, match="samples up to 20000 .*MaxSampleValue 16383"):
        raw.decode(tmp_path / "past.tif")


def test_two_pages_of_12_and_16_bits_each_get_their_white(tmp_path):
    with tifffile.TiffWriter(tmp_path / "two.tif") as writer:
        writer.write(np.full((20, 30), 4095, np.uint16), bitspersample=12,
                     photometric="minisblack")
        writer.write(np.full((20, 30), 9000, np.uint16), photometric="minisblack")
    meta = raw.decode(tmp_path / "two.tif", frame_names=["A", "B"])[1]
    assert meta["white_level"] == [4095.0, 65535.0]


@pytest.mark.parametrize("code", [2, 3, 4])
def test_a_ccitt_code_on_16_bit_samples_is_refused(tmp_path, code):
    """Compression 2/3/4 on 16-bit samples decoded to zeros, exit 0."""
    frame = (np.arange(64 * 96).reshape(64, 96) * 7 % 4000).astype(np.uint16)
    tifffile.imwrite(tmp_path / "p.tif", frame, photometric="minisblack")
    _patch(tmp_path / "p.tif", 259, code)
    with pytest.raises(InputError, match=f"Compression {code} \\(CCITT.*1-bit images\\) on "
                                         "16-bit samples"):
        raw.decode(tmp_path / "p.tif")


def test_a_photometric_cfa_tiff_without_dng_version_is_read_as_its_raw(tmp_path):
    """A TIFF/EP-style raw (no DNGVersion) was read as grey: black 0, white 65535, no CFA."""
    frame = np.random.default_rng(3).integers(600, 16000, (32, 48)).astype(np.uint16)
    write_dng(tmp_path / "d.dng", frame, cfa="GRBG", black_levels=[512], white_level=16383,
              active_area=[0, 0, 32, 48])
    with tifffile.TiffFile(tmp_path / "d.dng") as tif:
        tags = [(t.code, t.dtype, t.count, t.value, True) for t in tif.pages[0].tags.values()
                if t.code >= 33421 and t.code not in (50706, 50707)]
    tifffile.imwrite(tmp_path / "ep.tif", frame, photometric=32803, metadata=None,
                     extratags=tags)
    got, meta = raw.decode(tmp_path / "ep.tif")
    assert np.array_equal(got[0], frame) and meta["cfa"] == "GRBG"
    assert meta["black_level"] == [[512.0] * 4] and meta["white_level"] == [16383.0]


def test_a_grey_and_alpha_tiff_reads_as_the_grey_and_alpha_png(tmp_path):
    """The LA PNG was read, the same grey + alpha TIFF refused (contiguous or planar)."""
    pair = np.dstack([GREY, np.full_like(GREY, 255)])
    Image.fromarray(pair, "LA").save(tmp_path / "la.png")
    tifffile.imwrite(tmp_path / "la.tif", pair, photometric="minisblack", extrasamples=[2])
    tifffile.imwrite(tmp_path / "planar.tif", np.moveaxis(pair, -1, 0),
                     photometric="minisblack", extrasamples=[1], planarconfig="separate")
    png = raw.decode(tmp_path / "la.png")[0]
    for name in ("la.tif", "planar.tif"):
        got, meta = raw.decode(tmp_path / name)
        assert np.array_equal(got, png) and meta["views"] == ["raw"], name


@pytest.mark.parametrize("value,expected", [
    (b"Canon\0", "Canon"), (b"EOS 5D IV\0\0", "EOS 5D IV"), ("Nikon ", "Nikon")])
def test_text_tags_stored_as_bytes_are_text(value, expected):
    """A BYTE/UNDEFINED Make became the text "b'Canon\\x00'" in the photograph's EXIF."""
    assert rawmeta.exif_text(value) == expected


def test_bytes_that_are_no_text_are_dropped_without_a_repr():
    said = []
    kept = rawmeta.clean_exif({"Make": rawmeta.exif_text(b"Ca\xffnon\x01"),
                               "Model": rawmeta.exif_text(b"A" * 300)}, said.append)
    assert kept == {} and len(said) == 2
    assert not any("b'" in line or "\\x" in line for line in said), said


def test_codec_and_enum_words_are_plain():
    for text, words in (("imcd_lzw_decode returned IMCD_LZW_INVALID",
                         "its LZW data does not decode: invalid"),
                        ("ZSTD_decompress returned 'Unknown frame descriptor'",
                         "its Zstandard data does not decode: unknown frame descriptor"),
                        ("lzma_code returned LZMA_FORMAT_ERROR",
                         "its LZMA data does not decode: format error"),
                        ("<COMPRESSION.JPEG_99: 99> not supported",
                         "Compression 99 not supported")):
        assert plain_words(text) == words


@pytest.mark.parametrize("code,words", [(259, "Compression 99, a code no TIFF reader knows"),
                                        (258, "BitsPerSample 0 with SampleFormat 1")])
def test_a_header_value_no_reader_knows_is_named(tmp_path, code, words):
    tifffile.imwrite(tmp_path / "h.tif", np.ones((20, 30), np.uint16), photometric="minisblack")
    _patch(tmp_path / "h.tif", code, 99 if code == 259 else 0)
    with pytest.raises(InputError, match=words):
        raw.decode(tmp_path / "h.tif")


def test_pages_of_two_sample_types_name_their_types(tmp_path):
    with tifffile.TiffWriter(tmp_path / "mix.tif") as writer:
        writer.write(GREY.astype(np.uint16) * 200, photometric="minisblack")
        writer.write(GREY, photometric="minisblack")
    with pytest.raises(InputError, match=r"different types \(uint16 and uint8\)"):
        raw.decode(tmp_path / "mix.tif", frame_names=["A", "B"])


class _Page:
    """A TIFF page of the tags given (code -> value), as rawmeta reads them."""

    def __init__(self, tags: dict):
        self.tags = {code: type("Tag", (), {"value": value})() for code, value in tags.items()}


def test_colour_tags_of_the_wrong_count_are_dropped_with_a_warning():
    """audit 20 M3: an AsShotNeutral of 4 values or a ColorMatrix1 of 6 was dropped without
    the warning README promises (develop later said there was no as-shot white balance)."""
    pairs = (1000, 2225, 1, 1, 1000, 1261, 1, 1)  # 4 rationals
    matrix6 = tuple(v for x in (6446, -366, -864, -4436, 12204, 2513) for v in (x, 10000))
    said = []
    page = _Page({50728: pairs, 50721: matrix6, 50778: 21})
    rawmeta.clean_colour(rawmeta.dng_colour(page, page), said.append)
    assert any("as-shot white balance" in s and "dropped" in s for s in said)
    assert any("colour matrix" in s and "dropped" in s for s in said)
