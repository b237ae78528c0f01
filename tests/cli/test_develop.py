"""``plenocli develop`` end to end: colour from the raw's metadata, files read back, highlight
recovery, and every bad input refused with one line, exit 1 and nothing written."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner
from PIL import Image

from plenocli.cli.main import cli
from plenocli.colour.demosaic import mosaic
from plenocli.colour.metrics import delta_e_2000
from plenocli.io.dng import write_dng
from plenocli.io.tiffio import read_image, write_image
from plenocli.model.colour import rgb_to_xyz
from plenocli.synth.chart import camera_sampled, colour_chart

ROOT = Path(__file__).resolve().parents[2]
FIX = ROOT / "fixtures" / "dualpixel"
CAMERA = np.array([[0.80, 0.15, 0.05], [0.10, 0.80, 0.10], [0.05, 0.20, 0.75]]) \
    * np.array([[0.55], [1.0], [0.7]])  # camera RGB = CAMERA @ linear sRGB
BLACK, WHITE, DN = 512, 16383, 12000.0  # DN of a perfect white in green


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _chart_dng(path, *, color_matrix=None):
    truth, _ = colour_chart(160 * 4, 240 * 4)
    camera = camera_sampled(truth, 4) @ CAMERA.T
    raw = np.round(BLACK + DN * mosaic(camera, "RGGB")).astype(np.uint16)
    xyz_to_camera = CAMERA @ np.linalg.inv(rgb_to_xyz("srgb"))
    write_dng(path, raw, cfa="RGGB", black_levels=[BLACK], white_level=WHITE,
              active_area=[0, 0, *raw.shape], frame_names=["S"], model="Test Camera X",
              as_shot_neutral=CAMERA.sum(axis=1),
              color_matrix=(xyz_to_camera if color_matrix is None else color_matrix).ravel())


def _patch_means(rgb, patches):
    out = []
    for p in patches:
        r0, r1, c0, c1 = p.box
        dr, dc = (r1 - r0) // 4, (c1 - c0) // 4
        out.append(rgb[r0 + dr:r1 - dr, c0 + dc:c1 - dc].reshape(-1, 3).mean(axis=0))
    return np.array(out)


def test_raw_colour_metadata_gives_the_chart_colours(tmp_path):
    _chart_dng(tmp_path / "chart.dng")
    assert invoke("decode", tmp_path / "chart.dng", "-o", tmp_path / "f.tif").exit_code == 0
    result = invoke("develop", tmp_path / "f.tif", "-o", tmp_path / "chart.jpg", "--linear",
                    tmp_path / "lin.tif", "--preview", tmp_path / "p.png", "-q")
    assert result.exit_code == 0, result.output
    lin, meta = read_image(tmp_path / "lin.tif")
    assert meta["views"] == ["R", "G", "B"]
    _, patches = colour_chart(160, 240)
    measured = _patch_means(np.moveaxis(lin, 0, -1), patches) / (DN * CAMERA[1].sum())
    de = delta_e_2000(measured, np.array([p.rgb for p in patches]))
    assert de.mean() < 1.0 and de.max() < 2.0
    image = Image.open(tmp_path / "chart.jpg")
    assert image.size == (240, 160) and image.info.get("icc_profile")
    exif = image.getexif()
    assert exif[272] == "Test Camera X"
    record = json.loads(exif[270])["plenocli"]
    assert record["stage"] == "develop" and record["parameters"]["matrix"] == "as-shot"
    assert Image.open(tmp_path / "p.png").info.get("icc_profile")


def test_developing_the_linear_tiff_again_applies_nothing_twice(tmp_path):
    """audit 12: the linear TIFF carried the raw's as-shot gains and matrix, and develop applied
    them again (R x3.25, G x0.33, B x1.85, exit 0); as shot it is as developed, and a correction
    on top is only --wb."""
    _chart_dng(tmp_path / "chart.dng")
    invoke("decode", tmp_path / "chart.dng", "-o", tmp_path / "f.tif")
    assert invoke("develop", tmp_path / "f.tif", "-o", tmp_path / "a.tif", "--linear",
                  tmp_path / "a_lin.tif").exit_code == 0
    result = invoke("develop", tmp_path / "a_lin.tif", "-o", tmp_path / "b.tif", "--linear",
                    tmp_path / "b_lin.tif")
    assert result.exit_code == 0, result.output
    first, meta = read_image(tmp_path / "a_lin.tif")
    again, _ = read_image(tmp_path / "b_lin.tif")
    assert not (meta.get("colour") or {}).get("as_shot_wb")  # it is balanced already
    np.testing.assert_array_equal(again, first)
    np.testing.assert_array_equal(tifffile.imread(tmp_path / "b.tif"),
                                  tifffile.imread(tmp_path / "a.tif"))
    invoke("develop", tmp_path / "a_lin.tif", "--wb", "2,1,1", "-o", tmp_path / "c.jpg",
           "--linear", tmp_path / "c_lin.tif")
    warmer, _ = read_image(tmp_path / "c_lin.tif")
    np.testing.assert_allclose(warmer, first * np.array([2, 1, 1])[:, None, None], rtol=1e-6)


def test_sixteen_bit_tiff_in_display_p3(tmp_path):
    _chart_dng(tmp_path / "chart.dng")
    invoke("decode", tmp_path / "chart.dng", "-o", tmp_path / "f.tif")
    result = invoke("develop", tmp_path / "f.tif", "-o", tmp_path / "c.tif", "--space",
                    "display-p3", "--wb", "1.8,1,1.4", "--method", "bilinear")
    assert result.exit_code == 0, result.output
    with tifffile.TiffFile(tmp_path / "c.tif") as tif:
        page = tif.pages[0]
        assert page.dtype == np.uint16 and page.shape == (160, 240, 3)
        assert b"Display P3" in bytes(page.tags[34675].value)
        assert page.tags["Model"].value == "Test Camera X"


def test_highlight_recovery_rebuilds_exactly_the_clipped_s_pixels(tmp_path):
    for name in ("capture", "white"):
        invoke("decode", FIX / f"{name}.dng", "-o", tmp_path / f"{name}_f.tif")
        invoke("bias", tmp_path / f"{name}_f.tif", "-o", tmp_path / f"{name}_b.tif",
               "--smooth", 9)
    result = invoke("develop", tmp_path / "capture_b.tif", "--view", "S", "--wb-from",
                    tmp_path / "white_b.tif", "--matrix", "none", "--recover-highlights",
                    tmp_path / "white_b.tif", "-o", tmp_path / "s.png", "--linear",
                    tmp_path / "lin.tif")
    assert result.exit_code == 0, result.output
    lin, meta = read_image(tmp_path / "lin.tif")
    assert meta["views"] == ["R", "G", "B", "rebuilt"]
    truth = np.load(FIX / "truth.npz")
    expected = truth["capture_clipped_S"] & ~truth["capture_clipped_A"]
    assert expected.sum() > 0
    np.testing.assert_array_equal(lin[3] == 1, expected)
    # audit 24a W5, I1: a white whose split is not the capture's (A at 0.01 S: highlights
    # 20 x too bright, exit 0) or leaves (0, 1) (A = 1.5 S: "internal error") is refused
    white, meta = read_image(tmp_path / "white_b.tif")
    a, b, s = (meta["views"].index(v) for v in "ABS")
    for scale, words in ((0.01, "is not"), (1.5, "leaves (0, 1)"), (None, "column strip")):
        edited = white.copy()
        if scale is None:   # A and B swapped: the fall-off mirrored, its median the same
            edited[a], edited[b] = white[b], white[a]
        else:
            edited[a] = white[s] * scale
            edited[b] = white[s] - edited[a]
        write_image(tmp_path / "edited.tif", edited, meta)
        result = invoke("develop", tmp_path / "capture_b.tif", "--view", "S", "--wb", "1,1,1",
                        "--matrix", "none", "--recover-highlights", tmp_path / "edited.tif",
                        "-o", tmp_path / "out.png")
        assert result.exit_code == 1 and words in result.output, result.output
        assert "internal error" not in result.output and not (tmp_path / "out.png").exists()


def _refused(result, tmp_path, *words):
    assert result.exit_code == 1, result.output
    lines = [ln for ln in result.output.strip().splitlines() if ln]
    assert len(lines) == 1 and "Traceback" not in result.output
    for word in words:
        assert word in lines[0]
    assert not list(tmp_path.glob("out*")) and not list(tmp_path.glob(".out*"))


def test_mono_capture_is_refused(tmp_path):
    write_image(tmp_path / "mono.tif", np.ones((1, 16, 16), np.float32), {"views": ["raw"]})
    result = invoke("develop", tmp_path / "mono.tif", "-o", tmp_path / "out.jpg")
    _refused(result, tmp_path, "monochrome")


def test_unknown_cfa_is_refused(tmp_path):
    write_image(tmp_path / "v.tif", np.ones((1, 16, 16), np.float32),
                {"views": ["S"], "cfa": "RGBW"})
    result = invoke("develop", tmp_path / "v.tif", "-o", tmp_path / "out.tif", "--wb", "1,1,1")
    _refused(result, tmp_path, "RGBW")


def test_non_invertible_colour_matrix_is_refused(tmp_path):
    _chart_dng(tmp_path / "chart.dng", color_matrix=np.ones((3, 3)))
    invoke("decode", tmp_path / "chart.dng", "-o", tmp_path / "f.tif")
    result = invoke("develop", tmp_path / "f.tif", "-o", tmp_path / "out.jpg", "--linear",
                    tmp_path / "out_lin.tif")
    _refused(result, tmp_path, "not invertible")


@pytest.mark.parametrize("args, words", [
    (("--wb", "1,0,1"), ("--wb",)),
    (("--exposure", "nan"), ("--exposure",)),
    (("--space", "adobe"), ("--space",)),
])
def test_bad_options_are_usage_errors(tmp_path, args, words):
    write_image(tmp_path / "v.tif", np.ones((1, 16, 16), np.float32),
                {"views": ["S"], "cfa": "RGGB"})
    result = invoke("develop", tmp_path / "v.tif", "-o", tmp_path / "out.jpg", *args)
    assert result.exit_code == 2 and not list(tmp_path.glob("out*"))


def test_several_views_need_a_choice_and_missing_metadata_is_named(tmp_path):
    write_image(tmp_path / "v.tif", np.ones((2, 16, 16), np.float32),
                {"views": ["A", "S"], "cfa": "RGGB"})
    _refused(invoke("develop", tmp_path / "v.tif", "-o", tmp_path / "out.jpg"), tmp_path,
             "--view")
    _refused(invoke("develop", tmp_path / "v.tif", "--view", "S", "-o", tmp_path / "out.jpg"),
             tmp_path, "white balance")
    _refused(invoke("develop", tmp_path / "v.tif", "--view", "S", "--wb", "1,1,1", "-o",
                    tmp_path / "out.jpg"), tmp_path, "colour matrix")
    clash = invoke("develop", tmp_path / "v.tif", "--view", "S", "--wb", "1,1,1", "--matrix",
                   "none", "--space", "rec2020-linear", "-o", tmp_path / "out.jpg")
    assert clash.exit_code == 2 and "16 bits" in clash.output   # a usage error (audit 10 E5)
    assert not list(tmp_path.glob("out*"))


def test_bytes_of_the_tiff_are_the_output(tmp_path):
    """The atomic write leaves exactly one file per output (no temporaries)."""
    _chart_dng(tmp_path / "chart.dng")
    invoke("decode", tmp_path / "chart.dng", "-o", tmp_path / "f.tif")
    assert invoke("develop", tmp_path / "f.tif", "-o", tmp_path / "c.png").exit_code == 0
    assert not list(tmp_path.glob(".*part"))
    assert Image.open(io.BytesIO((tmp_path / "c.png").read_bytes())).format == "PNG"


def test_quad_bayer_sais_are_half_resolution_mosaics(tmp_path):
    """sai --cfa-layout micro-image: each SAI is a Bayer mosaic of its own; develop makes it RGB
    at the SAI's resolution."""
    colour = np.array([0.8, 0.3, 0.1])
    rows, cols = 64, 96
    block = np.indices((rows, cols)) // 2 % 2  # the 2 x 2 micro-image's place in RGGB
    channel = np.array([[0, 1], [1, 2]])[block[0], block[1]]
    frame = np.round(20000 * colour[channel]).astype(np.uint16)
    tifffile.imwrite(tmp_path / "quad.tif", frame)
    assert invoke("decode", tmp_path / "quad.tif", "--cfa", "RGGB", "-o",
                  tmp_path / "f.tif").exit_code == 0
    result = invoke("sai", tmp_path / "f.tif", "-n", 2, "--cfa-layout", "micro-image", "-o",
                    tmp_path / "views.tif")
    assert result.exit_code == 0, result.output
    result = invoke("develop", tmp_path / "views.tif", "--view", "S10", "--wb", "1,1,1",
                    "--matrix", "none", "-o", tmp_path / "s10.png", "--linear",
                    tmp_path / "lin.tif")
    assert result.exit_code == 0, result.output
    lin, _ = read_image(tmp_path / "lin.tif")
    assert lin.shape == (3, rows // 2, cols // 2)
    inner = np.moveaxis(lin, 0, -1)[4:-4, 4:-4]
    np.testing.assert_allclose(inner, np.broadcast_to(20000 * colour, inner.shape), rtol=1e-3)


def test_wb_from_a_dual_pixel_white_takes_its_sum_view_for_a_panorama(tmp_path):
    """A stitched panorama (pages R, G, B) has no view of the white's names: the gains come
    from the white's full-pupil sum S (here the only view without a green cast)."""
    cast = np.array([0.5, 1.0, 0.7], np.float32)
    pano = np.ones((3, 32, 48), np.float32) * cast[:, None, None] * 1000
    write_image(tmp_path / "pano.tif", pano, {"views": ["R", "G", "B"], "cfa": None})
    s_white = mosaic(np.ones((32, 48, 3), np.float32) * cast * 2000, "RGGB")
    skewed = mosaic(np.ones((32, 48, 3), np.float32) * [1.0, 2.0, 1.0] * 1000, "RGGB")
    write_image(tmp_path / "white.tif", np.stack([skewed, skewed, s_white]),
                {"views": ["A", "B", "S"], "cfa": "RGGB"})
    result = invoke("develop", tmp_path / "pano.tif", "--wb-from", tmp_path / "white.tif",
                    "--matrix", "none", "-o", tmp_path / "p.tif", "--linear",
                    tmp_path / "lin.tif")
    assert result.exit_code == 0, result.output
    lin, _ = read_image(tmp_path / "lin.tif")
    means = lin.reshape(3, -1).mean(axis=1)
    np.testing.assert_allclose(means / means[1], 1.0, atol=1e-4)   # neutral after S's gains
    # audit 24c W1: a white of another camera (both name their models) is refused
    for model, code in (("Camera B", 1), ("Camera A", 0)):
        write_image(tmp_path / "pano_a.tif", pano, {"views": ["R", "G", "B"], "cfa": None,
                                                    "exif": {"Model": "Camera A"}})
        write_image(tmp_path / "white_m.tif", np.stack([skewed, skewed, s_white]),
                    {"views": ["A", "B", "S"], "cfa": "RGGB", "exif": {"Model": model}})
        result = invoke("develop", tmp_path / "pano_a.tif", "--wb-from",
                        tmp_path / "white_m.tif", "--matrix", "none", "-o", tmp_path / "q.tif")
        assert result.exit_code == code, result.output
        assert code == 0 or "a white of another camera (Model Camera B" in result.output


def test_a_float_raws_decode_output_is_taken_above_its_black():
    """audit 20 W5: develop took integer decode output above its black level but a float DNG's
    as if black were 0 (512 DN of 16383 left in: a colour cast, exit 0)."""
    from plenocli.pipeline.stages.develop import _levels

    frames = np.full((1, 4, 4), 0.5, np.float32)
    frames[0, 0, 0] = 1.0
    meta = {"black_level": [[0.03125] * 4], "white_level": [1.0],
            "provenance": {"stage": "decode"}}
    out = _levels(frames, meta)
    assert np.isnan(out[0, 0, 0]) and np.allclose(out[0, 1:], 0.5 - 0.03125)
    views = dict(meta, provenance={"stage": "bias"})  # processed views: as they are
    assert np.array_equal(_levels(frames, views), frames)


def test_wb_from_takes_a_whites_sub_aperture_views(tmp_path):
    """audit 24c F1: the white's SAIs (sai output) were refused as wb-from, though its view of
    the same name is what docs/colour.md promises; their gains are the view's. A view named
    with spaces around is that view, as from YAML (audit 24a M2)."""
    cast = np.array([0.5, 1.0, 0.7], np.float32)
    views = np.ones((6, 16, 16), np.float32) * np.tile(cast, 2)[:, None, None] * 1000
    names = ["S00.R", "S00.G", "S00.B", "S01.R", "S01.G", "S01.B"]
    for name in ("white", "scene"):
        write_image(tmp_path / f"{name}.tif", views, {"views": names, "cfa": None,
                                                      "provenance": {"stage": "sai"}})
    result = invoke("develop", tmp_path / "scene.tif", "--view", " S01", "--wb-from",
                    tmp_path / "white.tif", "--matrix", "none", "-o", tmp_path / "p.tif",
                    "--linear", tmp_path / "lin.tif")
    assert result.exit_code == 0, result.output
    lin, _ = read_image(tmp_path / "lin.tif")
    np.testing.assert_allclose(lin.reshape(3, -1).mean(axis=1), lin[1].mean(), rtol=1e-4)
