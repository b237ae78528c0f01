"""White balance, camera matrices, ICC profiles and exported files, against known answers."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import tifffile
from PIL import Image, ImageCms

from plenocli.colour import balance
from plenocli.colour import develop as dev
from plenocli.colour.demosaic import mosaic
from plenocli.colour.metrics import delta_e_2000
from plenocli.io import icc
from plenocli.io import photo as export
from plenocli.model import colour as matrix
from plenocli.synth.chart import GREY_CARD, camera_sampled, colour_chart

CAMERA_GAIN = np.array([0.55, 1.0, 0.7])  # the simulator's CFA colour gains (synth.dualpixel)
MIXING = np.array([[0.80, 0.15, 0.05], [0.10, 0.80, 0.10], [0.05, 0.20, 0.75]])


def _patch_means(rgb, patches, inset=0.25):
    out = []
    for p in patches:
        r0, r1, c0, c1 = p.box
        dr, dc = int((r1 - r0) * inset), int((c1 - c0) * inset)
        out.append(np.nanmean(rgb[r0 + dr:r1 - dr, c0 + dc:c1 - dc].reshape(-1, 3), axis=0))
    return np.array(out)


def _grey_card(patches):
    return next(p for p in patches if p.name == GREY_CARD)


def _camera_capture(camera_matrix):
    """The chart through a camera: camera RGB = camera_matrix @ linear sRGB, Bayer, demosaiced."""
    truth, patches = colour_chart(192 * 4, 288 * 4)
    scene = camera_sampled(truth, 4)
    _, patches = colour_chart(192, 288)
    camera = scene @ camera_matrix.T
    view = dev.ColourView("S", (0,), "RGGB")
    return dev.camera_rgb(mosaic(camera, "RGGB")[np.newaxis], view), patches


def _crop(rgb, box):
    r0, r1, c0, c1 = box
    dr, dc = (r1 - r0) // 4, (c1 - c0) // 4
    return rgb[r0 + dr:r1 - dr, c0 + dc:c1 - dc]


def test_grey_card_white_balance_is_within_one_delta_e():
    camera, patches = _camera_capture(np.diag(CAMERA_GAIN))
    card = _grey_card(patches)
    gains = balance.gains_from_rgb(_crop(camera, card.box), centre_fraction=1.0)
    card_camera = CAMERA_GAIN * np.array(card.rgb)  # the card itself is a touch off neutral
    np.testing.assert_allclose(gains, card_camera[1] / card_camera, rtol=2e-3)
    balanced = balance.apply_gains(camera, gains)
    measured = _patch_means(balanced, patches)
    truth = np.array([p.rgb for p in patches])
    de = delta_e_2000(measured, truth)
    assert de[patches.index(card)] < 1.0
    assert de.max() < 1.0


def test_camera_matrix_restores_the_chart_colours():
    camera_matrix = MIXING * CAMERA_GAIN[:, None]
    xyz_to_camera = camera_matrix @ np.linalg.inv(matrix.rgb_to_xyz("srgb"))
    camera, patches = _camera_capture(camera_matrix)
    card = _grey_card(patches)
    gains = balance.gains_from_rgb(_crop(camera, card.box), centre_fraction=1.0)
    scene = dev.scene_rgb(camera, gains=gains, camera_to_srgb=matrix.camera_to_srgb(xyz_to_camera))
    # the balanced camera keeps green's row sum as its scale (dcraw's convention)
    measured = _patch_means(scene, patches) / camera_matrix[1].sum()
    de = delta_e_2000(measured, np.array([p.rgb for p in patches]))
    assert de.mean() < 1.0 and de.max() < 2.0


@pytest.mark.parametrize("bad", [np.zeros((3, 3)), [[1, 2, 3], [2, 4, 6], [0, 1, 0]],
                                 [[1, 0, 0], [0, np.nan, 0], [0, 0, 1]], np.eye(2)])
def test_non_invertible_colour_matrix_is_refused(bad):
    with pytest.raises(ValueError, match="matrix"):
        matrix.camera_to_srgb(bad)


@pytest.mark.parametrize("gains", [(1, 0, 1), (1, -1, 1), (1, float("nan"), 1), (1, 2)])
def test_bad_gains_are_refused(gains):
    with pytest.raises(ValueError, match="gains"):
        balance.normalised_gains(gains)


def test_gains_from_a_white_mosaic():
    frame = mosaic(np.full((32, 48, 3), 1.0) * CAMERA_GAIN * 1000, "BGGR")
    frame[10, 10] = np.nan
    np.testing.assert_allclose(balance.gains_from_mosaic(frame, "BGGR"), 1 / CAMERA_GAIN,
                               rtol=1e-12)


def _srgb_encode(x):
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


@pytest.mark.parametrize("space", ["display-p3", "rec2020-linear"])
def test_icc_profiles_convert_like_colour_science(space):
    """LittleCMS (through Pillow) reads our profile and converts to its own sRGB like the
    published primaries say."""
    rng = np.random.default_rng(7)
    linear_srgb = 0.1 + 0.8 * rng.random((16, 3))
    in_space = linear_srgb @ matrix.srgb_to_space(space).T
    assert np.all((in_space > 0) & (in_space < 1))
    encoded = export.encode(in_space, space)
    image = Image.fromarray(np.round(encoded * 255).astype(np.uint8).reshape(4, 4, 3))
    ours = ImageCms.ImageCmsProfile(io.BytesIO(icc.profile_bytes(space)))
    srgb = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB"))
    transform = ImageCms.buildTransform(ours, srgb, "RGB", "RGB", renderingIntent=1)
    converted = np.asarray(ImageCms.applyTransform(image, transform), float).reshape(16, 3)
    expected = np.round(_srgb_encode(linear_srgb) * 255)
    tol = 2 if space == "display-p3" else 6  # linear 8-bit input quantises the darks
    np.testing.assert_allclose(converted, expected, atol=tol)


EXIF = {"Make": "Canon", "Model": "Canon EOS 5D Mark IV", "ExposureTime": 1 / 125,
        "FNumber": 8.0, "ISO": 200, "LensModel": "EF50mm f/1.8 STM",
        "DateTimeOriginal": "2026:01:02 03:04:05"}


@pytest.mark.parametrize("fmt", ["jpeg", "png"])
def test_jpeg_and_png_carry_icc_exif_and_provenance(fmt):
    encoded = np.random.default_rng(1).random((20, 30, 3)).astype(np.float32)
    body = export.image_bytes(encoded, fmt, space="display-p3", exif=EXIF,
                              description={"plenocli": {"stage": "develop"}})
    image = Image.open(io.BytesIO(body))
    assert image.format == fmt.upper() and image.size == (30, 20)
    assert image.info["icc_profile"] == icc.profile_bytes("display-p3")
    exif = image.getexif()
    assert exif[271] == "Canon" and exif[272] == "Canon EOS 5D Mark IV"
    assert json.loads(exif[270])["plenocli"]["stage"] == "develop"
    sub = exif.get_ifd(export.EXIF_IFD)
    assert float(sub[33434]) == pytest.approx(1 / 125) and float(sub[33437]) == 8.0
    assert sub[34855] == 200 and sub[42036] == "EF50mm f/1.8 STM"


def test_tiff_is_16_bit_with_icc_exif_and_provenance():
    encoded = np.linspace(0, 1, 20 * 30 * 3, dtype=np.float32).reshape(20, 30, 3)
    body = export.image_bytes(encoded, "tiff", space="rec2020-linear", exif=EXIF,
                              description={"plenocli": {"stage": "develop"}})
    with tifffile.TiffFile(io.BytesIO(body)) as tif:
        page = tif.pages[0]
        data = page.asarray()
        tags = page.tags
        assert data.dtype == np.uint16 and data.shape == (20, 30, 3)
        np.testing.assert_array_equal(data, np.round(encoded * 65535))
        assert bytes(tags[34675].value) == icc.profile_bytes("rec2020-linear")
        assert tags["Make"].value == "Canon" and tags["Model"].value == "Canon EOS 5D Mark IV"
        assert tags[33434].value == (1, 125) and tags[34855].value == 200
        assert json.loads(page.description)["plenocli"]["stage"] == "develop"


def test_linear_rec2020_is_refused_in_8_bit():
    with pytest.raises(ValueError, match="16 bits"):
        export.image_bytes(np.zeros((4, 4, 3)), "jpeg", space="rec2020-linear", exif=None,
                           description={})


def test_colour_views_refuse_mono_and_single_colour_views():
    with pytest.raises(ValueError, match="monochrome"):
        dev.colour_views(["raw"])
    with pytest.raises(ValueError, match="single colour"):
        dev.colour_views(["S00", "S01", "S10", "S11"], view_colours=["R", "G", "G", "B"])
    views = dev.colour_views(["S00", "S01"], view_colours=["RGGB", "RGGB"])
    assert [v.cfa for v in views] == ["RGGB", "RGGB"]
    views = dev.colour_views(["S00.R", "S00.G", "S00.B", "S01.R", "S01.G", "S01.B"])
    assert [(v.name, v.pages) for v in views] == [("S00", (0, 1, 2)), ("S01", (3, 4, 5))]
    sweep = dev.colour_views(["R@g3", "G@g3", "B@g3", "R@g4", "G@g4", "B@g4"])
    assert [(v.name, v.pages) for v in sweep] == [("RGB@g3", (0, 1, 2)), ("RGB@g4", (3, 4, 5))]


def test_bayer_previews_are_in_the_cameras_colour(tmp_path):
    """A grey scene through the camera's filters shows grey (not green) in a preview, with the
    as-shot gains and, without them, with a grey-world balance."""
    import cv2

    from plenocli.io.preview import write_png

    frame = mosaic(np.full((64, 96, 3), 0.4) * CAMERA_GAIN, "RGGB").astype(np.float32)
    for colour in ({"as_shot_wb": list(1 / CAMERA_GAIN), "xyz_to_camera": None}, None):
        write_png(tmp_path / "p.png", frame, cfa="RGGB", colour=colour)
        bgr = cv2.imread(str(tmp_path / "p.png")).astype(int)
        assert bgr.shape == (32, 48, 3)
        assert np.abs(bgr - bgr[..., 1:2]).max() <= 1 and bgr.mean() > 200


def test_libraw_colour_metadata_is_mapped_by_colour_index():
    """LibRaw indexes white balance and matrix rows by colour (color_desc), not by position."""
    from types import SimpleNamespace

    from plenocli.io.rawmeta import rawpy_colour

    cam_xyz = np.array([[0.6, -0.1, -0.05], [-0.4, 1.2, 0.2], [-0.1, 0.17, 0.62], [0, 0, 0]])
    raw = SimpleNamespace(camera_whitebalance=[1.5, 1.0, 2.5, 1.0], rgb_xyz_matrix=cam_xyz)
    colour = rawpy_colour(raw, "BGRG")  # blue is colour 0 here
    assert colour["as_shot_wb"] == [2.5, 1.0, 1.5]
    np.testing.assert_array_equal(colour["xyz_to_camera"], cam_xyz[[2, 1, 0]])
    empty = rawpy_colour(SimpleNamespace(camera_whitebalance=[0, 0, 0, 0],
                                          rgb_xyz_matrix=np.zeros((4, 3))), "RGBG")
    assert empty == {"as_shot_wb": None, "xyz_to_camera": None}


def test_raw_frame_previews_take_off_the_black_level(tmp_path):
    import cv2

    from plenocli.io.preview import write_png

    scene = np.ones((64, 96, 3))
    scene[:, :48] = 0.0  # half the frame black: it must show black, not the black level
    frame = 2048 + mosaic(scene * 8000 * CAMERA_GAIN, "RGGB").astype(np.float32)
    write_png(tmp_path / "p.png", frame, cfa="RGGB")
    bgr = cv2.imread(str(tmp_path / "p.png")).astype(int)
    assert bgr[:, :20].max() <= 2 and bgr[:, 30:].min() >= 250


def test_blown_highlights_are_the_enclosed_masked_pixels():
    scene = np.ones((20, 30, 3), np.float32)
    scene[5:8, 10:14, 1] = np.nan  # a clipped highlight (one channel is enough)
    scene[:, :3] = np.nan  # outside the views of a panorama: reaches the edge
    inside = np.zeros((20, 30), bool)
    inside[5:8, 10:14] = True
    np.testing.assert_array_equal(dev.blown_highlights(scene, whole_frame=False), inside)
    everything = inside.copy()
    everything[:, :3] = True
    np.testing.assert_array_equal(dev.blown_highlights(scene, whole_frame=True), everything)


@pytest.mark.parametrize("cfa, pages", [("RGGB", ["raw"]), (None, ["R", "G", "B"])])
def test_values_too_small_for_float32_to_scale_are_refused_as_such(cfa, pages):
    # audit 7 E13: finite denormal pixels (1e-44 .. 1e-40) were called "no finite pixel": the
    # demosaic's and the exposure's 1 / value overflowed to inf
    rng = np.random.default_rng(4)
    data = (rng.uniform(1e-44, 1e-40, (len(pages), 16, 24))).astype(np.float32)
    view = dev.colour_views(pages, cfa=cfa, view_colours=None)[0]
    with pytest.raises(ValueError, match=r"largest value is 9.9\d*e-41, below float32.s normal"):
        dev.camera_rgb(data, view, gains=np.ones(3))
    normal = dev.camera_rgb(data * np.float32(1e30), view, gains=np.ones(3))
    assert np.isfinite(normal).all()
