"""Decoding: frames really are the file's frames, metadata is right, bad files are refused."""

import re

import numpy as np
import pytest
import rawpy
import tifffile

from plenocli.errors import InputError
from plenocli.io import raw as rawio
from plenocli.io.dng import write_dng
from plenocli.synth.dualpixel import dng_options, dualpixel_capture


@pytest.fixture
def capture(tmp_path):
    raw, truth = dualpixel_capture(seed=3, rows=64, cols=96, top=8, left=32)
    path = tmp_path / "capture.dng"
    write_dng(path, raw, **dng_options(truth))
    return path, raw, truth


def test_second_frame_is_the_files_second_frame(capture):
    path, raw, _ = capture
    assert not np.array_equal(raw[0], raw[1])  # the fixture's frames differ
    frames, meta = rawio.decode(path)
    assert meta["views"] == ["S", "A"]
    np.testing.assert_array_equal(frames[0], raw[0])
    np.testing.assert_array_equal(frames[1], raw[1])  # frame 1 (A), not frame 0 again


def test_libraw_agrees_on_the_first_frame(capture):
    path, raw, _ = capture
    with rawpy.imread(str(path)) as r:
        np.testing.assert_array_equal(r.raw_image, raw[0])


def test_metadata_carries_geometry_cfa_and_levels(capture):
    path, _, truth = capture
    _, meta = rawio.decode(path)
    geo = truth["geometry"]
    assert meta["cfa"] == "RGGB"
    assert meta["active_area"] == geo["active_area"]
    assert meta["masked_areas"] == geo["masked_areas"]
    assert meta["white_level"] == [15000.0, 15000.0]
    assert meta["black_level"][1] == [2036.0] * 4


def _fake_cr2(monkeypatch, tmp_path, flip: int = 0):
    """A CR2 path whose LibRaw reading is faked: the same frame for shot 0 and 1, LibRaw's
    image flip ``flip``."""
    data = np.arange(64 * 96, dtype=np.uint16).reshape(64, 96)

    class FakeRaw:
        raw_image = data
        raw_pattern = np.array([[0, 1], [3, 2]])
        color_desc = b"RGBG"
        black_level_per_channel = [512, 512, 512, 512]
        white_level = 15000
        sizes = type("S", (), {"top_margin": 8, "left_margin": 32, "height": 56, "width": 64,
                               "flip": flip})

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

    monkeypatch.setattr(rawpy, "imread", lambda path, shot_select=0: FakeRaw())
    path = tmp_path / "IMG.CR2"
    path.write_bytes(b"II*\x00\x10\x00\x00\x00CR\x02\x00" + bytes(100))
    return path


@pytest.mark.parametrize("flip,orientation", [(0, 1), (3, 3), (5, 8), (6, 6), (1, 2), (4, 5)])
def test_canon_orientation_from_libraw_flip(monkeypatch, tmp_path, flip, orientation):
    """A CR2's orientation is LibRaw's sizes.flip as the EXIF value (audit 15 W3: dropped)."""
    _, meta = rawio.decode(_fake_cr2(monkeypatch, tmp_path, flip))
    assert meta["orientation"] == orientation


def test_canon_flip_libraw_does_not_define_is_refused(monkeypatch, tmp_path):
    with pytest.raises(InputError, match="flip 9 .*tag 274"):
        rawio.decode(_fake_cr2(monkeypatch, tmp_path, 9))


def test_canon_path_refuses_a_raw_whose_frames_are_the_same(monkeypatch, tmp_path):
    """LibRaw may return frame 0 for shot_select=1: decode must notice, not trust it."""
    path = _fake_cr2(monkeypatch, tmp_path)
    with pytest.raises(InputError, match="same frame for frame 0 and frame 1"):
        rawio.decode(path, camera="canon-dp")
    frames, meta = rawio.decode(path)  # auto: one frame, honestly reported
    assert frames.shape[0] == 1 and meta["views"] == ["S"]


def test_rawpy_black_levels_mapped_by_colour_not_position():
    class R:
        black_level_per_channel = [100, 200, 300, 400]  # indexed by colour R, G, B, G2
        raw_pattern = np.array([[1, 0], [2, 3]])  # GRBG
    assert rawio._black_by_position(R) == [200, 100, 300, 400]


def test_truncated_dng_is_refused(capture, tmp_path):
    path, _, _ = capture
    cut = tmp_path / "cut.dng"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 3])
    with pytest.raises(InputError, match="truncated"):
        rawio.decode(cut)


def test_not_a_raw_is_refused(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_text("hello")
    with pytest.raises(InputError, match="not a raw capture"):
        rawio.decode(path)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_plain_tiff_and_png_with_given_levels(tmp_path, dtype):
    import cv2

    data = np.random.default_rng(0).integers(0, 200, (20, 30)).astype(dtype)
    tifffile.imwrite(tmp_path / "x.tif", data)
    cv2.imwrite(str(tmp_path / "x.png"), data)
    for name in ("x.tif", "x.png"):
        frames, meta = rawio.decode(tmp_path / name, black=16, white=250, cfa="grbg")
        np.testing.assert_array_equal(frames[0], data)
        assert meta["black_level"] == [[16.0] * 4] and meta["white_level"] == [250.0]
        assert meta["cfa"] == "GRBG" and meta["camera"] == "image"


def test_rgb_png_gives_three_views(tmp_path):
    import cv2

    rgb = np.zeros((8, 10, 3), np.uint8)
    rgb[..., 0] = 200  # red
    cv2.imwrite(str(tmp_path / "c.png"), rgb[..., ::-1])
    frames, meta = rawio.decode(tmp_path / "c.png")
    assert meta["views"] == ["R", "G", "B"]
    assert frames[0].max() == 200 and frames[2].max() == 0


def test_bad_cfa_is_refused(tmp_path):
    tifffile.imwrite(tmp_path / "x.tif", np.zeros((4, 4), np.uint16))
    with pytest.raises(InputError, match="not a 2 x 2 Bayer pattern"):
        rawio.decode(tmp_path / "x.tif", cfa="RGGX")


@pytest.mark.parametrize("levels,words", [
    (dict(black=float("nan")), "black level"), (dict(black=-3.0), "black level"),
    (dict(white=-5.0), "white level"), (dict(white=float("nan")), "white level"),
    (dict(black=900.0, white=800.0), "white level 800 must be above the black level 900"),
])
def test_levels_must_be_finite_and_ordered(tmp_path, levels, words):
    tifffile.imwrite(tmp_path / "s.tif", np.ones((8, 8), np.uint16))
    with pytest.raises(InputError, match=words):
        rawio.decode(tmp_path / "s.tif", **levels)


def test_dng_active_area_beyond_the_image_is_refused(tmp_path):
    from plenocli.io.dng import write_dng

    write_dng(tmp_path / "x.dng", np.zeros((1, 16, 16), np.uint16), cfa="RGGB",
              black_levels=[0], white_level=1000, active_area=[0, 0, 4000, 6000])
    with pytest.raises(InputError, match="active_area"):
        rawio.decode(tmp_path / "x.dng")


def test_frames_names_a_dngs_unnamed_frames_only(tmp_path):
    # own-5 (round 10): --frames A,S relabelled the S and A a DNG names (bias then wrote the
    # real S as A); a DNG whose IFDs name no frame (frame0, frame1) still takes names
    from plenocli.errors import OptionError

    frames = np.arange(2 * 16 * 16, dtype=np.uint16).reshape(2, 16, 16)
    options = dict(cfa="RGGB", black_levels=[0, 0], white_level=1000, active_area=[0, 0, 16, 16])
    write_dng(tmp_path / "named.dng", frames, frame_names=["S", "A"], **options)
    write_dng(tmp_path / "unnamed.dng", frames, **options)
    with pytest.raises(OptionError, match=r"names its own frames \(S,A\)"):
        rawio.decode(tmp_path / "named.dng", frame_names=["A", "S"])
    got, meta = rawio.decode(tmp_path / "unnamed.dng", frame_names=["S", "A"])
    assert meta["views"] == ["S", "A"] and np.array_equal(got, frames)


@pytest.mark.parametrize("compression", [("jpeg", {"lossless": True}), ("zlib", None)])
def test_compressed_dng_decodes_as_the_uncompressed_one(tmp_path, compression):
    """Cameras and Adobe's converter write DNGs in lossless-JPEG tiles: the same frames."""
    rng = np.random.default_rng(5)
    frames = rng.integers(500, 15000, (2, 300, 420)).astype(np.uint16)
    write_dng(tmp_path / "plain.dng", frames, cfa="RGGB", black_levels=[512, 512],
                  white_level=16383, active_area=[2, 4, 300, 420])
    with tifffile.TiffFile(tmp_path / "plain.dng") as tif:
        tags = [[(t.code, t.dtype, t.count, t.value, True) for t in page.tags.values()
                 if t.code >= 33421] for page in tif.pages]
    name, args = compression
    with tifffile.TiffWriter(tmp_path / "packed.dng") as writer:
        for k, frame in enumerate(frames):
            writer.write(frame, photometric=32803, compression=name, compressionargs=args,
                         tile=(128, 128), subfiletype=0, description=f"frame{k}",
                         metadata=None, extratags=tags[k])
    with tifffile.TiffFile(tmp_path / "packed.dng") as tif:
        assert tif.pages[0].compression != 1 and tif.pages[0].is_tiled
    plain, plain_meta = rawio.decode(tmp_path / "plain.dng")
    packed, packed_meta = rawio.decode(tmp_path / "packed.dng")
    assert np.array_equal(packed, plain) and packed_meta["cfa"] == plain_meta["cfa"]
    if name == "zlib":   # a damaged tile is refused as damage (the codec is there)
        with tifffile.TiffFile(tmp_path / "packed.dng") as tif:
            start = tif.pages[0].dataoffsets[0]
        data = bytearray((tmp_path / "packed.dng").read_bytes())
        data[start + 100:start + 2100] = bytes(2000)   # inside the first tile
        (tmp_path / "damaged.dng").write_bytes(bytes(data))
        with pytest.raises(InputError, match="damaged"):
            rawio.decode(tmp_path / "damaged.dng")


@pytest.mark.parametrize("second, words", [
    (np.zeros((12, 40), np.uint16), "2 pages of different sizes .page shapes 24 x 40, 12 x 40. "
                                    "not marked as reduced-resolution previews"),
    (np.zeros((24, 40), np.float32), "2 full-size pages .page shape 24 x 40."),
    (np.zeros((24, 40, 3), np.uint16), "different sizes .page shapes 24 x 40, 24 x 40 x 3"),
    (np.ones((24, 40), np.uint16), "2 full-size pages .page shape 24 x 40."),
])
def test_a_multi_page_tiff_is_refused_not_read_as_its_first_page(tmp_path, second, words):
    with tifffile.TiffWriter(tmp_path / "two.tif") as tif:
        tif.write(np.ones((24, 40), np.uint16))
        tif.write(second)
    with pytest.raises(InputError, match=words):
        rawio.decode(tmp_path / "two.tif")


def test_grey_pages_each_named_by_frames_are_the_frames(tmp_path):
    """audit 9 E14: two images of a dual-pixel pair (the Pixel 4's PNGs) could not become one
    A/B file; a TIFF of grey pages of one size and type, one --frames name each, can."""
    pages = np.random.default_rng(2).integers(0, 4000, (2, 24, 40)).astype(np.uint16)
    with tifffile.TiffWriter(tmp_path / "pair.tif") as tif:
        for page in pages:
            tif.write(page)
    frames, meta = rawio.decode(tmp_path / "pair.tif", frame_names=["A", "B"])
    np.testing.assert_array_equal(frames, pages)
    assert meta["views"] == ["A", "B"]
    with pytest.raises(InputError, match="or grey pages each named by --frames .2 names"):
        rawio.decode(tmp_path / "pair.tif")
    with tifffile.TiffWriter(tmp_path / "mixed.tif") as tif:
        tif.write(pages[0])
        tif.write(pages[1].astype(np.float32))
    with pytest.raises(InputError, match=r"different types \(float32 and uint16\)"):
        rawio.decode(tmp_path / "mixed.tif", frame_names=["A", "B"])


def test_a_planar_rgb_tiff_decodes_as_its_contiguous_twin(tmp_path):
    """audit 7 E3: PlanarConfiguration 2 (one plane per colour) was refused as an image of
    shape (3, rows, cols); it is the same RGB image as the contiguous file."""
    rgb = np.random.default_rng(6).integers(0, 60000, (24, 40, 3)).astype(np.uint16)
    tifffile.imwrite(tmp_path / "contig.tif", rgb, photometric="rgb", planarconfig="contig")
    tifffile.imwrite(tmp_path / "planar.tif", np.moveaxis(rgb, -1, 0), photometric="rgb",
                     planarconfig="separate")
    planar, meta = rawio.decode(tmp_path / "planar.tif")
    contig, _ = rawio.decode(tmp_path / "contig.tif")
    assert meta["views"] == ["R", "G", "B"]
    np.testing.assert_array_equal(planar, np.moveaxis(rgb, -1, 0))
    np.testing.assert_array_equal(planar, contig)


def test_a_reduced_resolution_preview_beside_the_image_is_not_a_page_of_it(tmp_path):
    image = np.random.default_rng(4).integers(0, 4000, (24, 40)).astype(np.uint16)
    with tifffile.TiffWriter(tmp_path / "one.tif") as tif:
        tif.write(image[::4, ::4], subfiletype=1)
        tif.write(image)
    frames, _ = rawio.decode(tmp_path / "one.tif")
    np.testing.assert_array_equal(frames[0], image)
    # audit 24 F2: nor is a transparency mask (NewSubfileType 4), refused as "a 1-bit TIFF"
    with tifffile.TiffWriter(tmp_path / "masked.tif") as tif:
        tif.write(image, photometric="minisblack", metadata=None)
        tif.write(np.ones(image.shape, bool), photometric="minisblack", subfiletype=4,
                  metadata=None)
    frames, _ = rawio.decode(tmp_path / "masked.tif")
    np.testing.assert_array_equal(frames[0], image)


def test_a_camera_the_file_is_not_is_named_not_blamed_on_damage(capture, tmp_path):
    """audit 7 E20: --camera image on a DNG said "truncated, damaged", --camera dng on a plain
    TIFF "the DNG is damaged", --camera canon-dp on a dual-pixel DNG "not a dual-pixel file"."""
    dng = capture[0]
    tifffile.imwrite(tmp_path / "plain.tif", np.ones((8, 8), np.uint16))
    for path, camera, words in ((dng, "image", "is a DNG, not a plain image"),
                                (dng, "canon-dp", "is a DNG, not a Canon CR2 raw"),
                                (tmp_path / "plain.tif", "dng", "is a plain image (TIFF, PNG or "
                                                                "BMP), not a DNG")):
        with pytest.raises(InputError, match=re.escape(words) + ".*use --camera"):
            rawio.decode(path, camera=camera)
