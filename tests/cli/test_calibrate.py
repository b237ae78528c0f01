"""End-to-end `plenocli calibrate`: outputs, and bad input giving one line, exit 1, no output."""

from __future__ import annotations

import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import InputError
from plenocli.pipeline.stages.calibrate import _pitch_error, _refuse_hidden_mosaic
from plenocli.pipeline.stages.simulate import simulate
from plenocli.synth.whiteimage import white_image


def test_calibrate_writes_yaml_xml_preview(tmp_path):
    image, _ = white_image((512, 512), pitch_px=15.3, angle_rad=0.2, offset_xy=(250.3, 260.1),
                           seed=1)
    src = tmp_path / "white.tif"
    tifffile.imwrite(src, image)
    out, xml, png = tmp_path / "g.yaml", tmp_path / "g.xml", tmp_path / "g.png"
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--xml", str(xml),
                                   "--preview", str(png), "--compare", str(xml)[:-4] + "x.xml"])
    assert res.exit_code == 1 and not out.exists()   # --compare file missing
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--xml", str(xml),
                                   "--preview", str(png)])
    assert res.exit_code == 0, res.output
    doc = yaml.safe_load(out.read_text())
    assert abs(doc["lens_grid"]["pitch_px"] - 15.3) < 0.01
    assert doc["residuals"]["residual_rms_px"] < 0.1
    assert xml.exists() and png.exists()
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(tmp_path / "h.yaml"),
                                   "--compare", str(xml)])
    assert res.exit_code == 0, res.output
    cmp = yaml.safe_load((tmp_path / "h.yaml").read_text())["compare"]
    assert cmp["max_px"] < 0.2   # refined centres (noisy) against their own fitted lattice


@pytest.mark.parametrize("kind", ["noise", "flat", "small"])
def test_bad_images(tmp_path, kind):
    rng = np.random.default_rng(0)
    data = {"noise": rng.normal(1000, 40, (400, 400)), "flat": np.full((400, 400), 900.0),
            "small": np.ones((30, 30))}[kind].astype(np.uint16)
    src, out = tmp_path / "in.tif", tmp_path / "out.yaml"
    tifffile.imwrite(src, data)
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out)])
    assert res.exit_code == 1
    assert res.output.strip().count("\n") == 0 and "Error" in res.output
    assert not out.exists()


def test_a_white_with_unknown_pixels_is_refused_with_what_to_give(tmp_path):
    """audit 9 E11: a flat or bias output holding NaN (floored, clipped) was told "pass a
    decoded frame"; it is told which pixels and which file calibrate takes."""
    image, _ = white_image((256, 256), pitch_px=15.3, angle_rad=0.2, offset_xy=(120.3, 130.1),
                           seed=1)
    image = image.astype(np.float32)
    image[10, 20] = image[100, 7] = np.nan
    src, out = tmp_path / "in.tif", tmp_path / "out.yaml"
    tifffile.imwrite(src, image)
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out)])
    assert res.exit_code == 1 and not out.exists()
    assert res.output.strip() == (f"Error: {src}: 2 pixel(s) are unknown (NaN: clipped, or below "
                                  "flat's --floor); calibrate reads every pixel: give the decode "
                                  "output of this capture (its black level is subtracted here)")


def test_corrupt_xml(tmp_path):
    image, _ = white_image((256, 256), pitch_px=15.0, angle_rad=0.2, offset_xy=(128, 128))
    src, bad, out = tmp_path / "w.tif", tmp_path / "bad.xml", tmp_path / "o.yaml"
    tifffile.imwrite(src, image)
    bad.write_text("<RayCalibData><offset><x>1")
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--compare", str(bad)])
    assert res.exit_code == 1 and "malformed XML" in res.output and not out.exists()


def test_lattice_kind_that_does_not_fit_is_refused(tmp_path):
    image, _ = white_image((512, 512), pitch_px=15.3, angle_rad=0.2, offset_xy=(250.3, 260.1),
                           lattice="square", seed=2)
    src, out = tmp_path / "white.tif", tmp_path / "g.yaml"
    tifffile.imwrite(src, image)
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--lattice", "hex"])
    assert res.exit_code == 1 and "square" in res.output and not out.exists()
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert yaml.safe_load(out.read_text())["lens_grid"]["lattice"] == "square"


@pytest.mark.parametrize("value", ["nan", "inf", "2", "300"])
def test_pitch_option_refuses_bad_values(tmp_path, value):
    res = CliRunner().invoke(cli, ["calibrate", str(tmp_path / "x.tif"), "-o",
                                   str(tmp_path / "g.yaml"), "--pitch", value])
    assert res.exit_code == 2


def test_start_and_lens_types_in_yaml_and_xml(tmp_path):
    from plenocli.io import raytrix
    from plenocli.model.lensgrid import LensGrid
    from plenocli.synth.lenslet import lenslet_scene

    image, truth = lenslet_scene((840, 840), pitch_px=35.0, angle_rad=0.3, multi_focus=True,
                                 seed=3)
    src = tmp_path / "scene.tif"
    tifffile.imwrite(src, image)
    off = np.asarray(truth["offset_xy"]) + (0.8, -0.6)
    start = LensGrid(35.0, 0.3, tuple(off), image_shape=(840, 840))
    xml_in, out, xml = tmp_path / "start.xml", tmp_path / "g.yaml", tmp_path / "g.xml"
    raytrix.write_calib(xml_in, raytrix.calib_from_grid(start))
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--start",
                                   str(xml_in), "--xml", str(xml)])
    assert res.exit_code == 0, res.output
    doc = yaml.safe_load(out.read_text())
    assert doc["moved_from_start"]["rms_px"] > 0.5
    # the scene's types differ in blur at every depth: no depth decides, so no types
    assert doc["lens_grid"].get("lens_type_of_coset") is None
    assert doc["residuals"]["confidence"]["contrast"] > 0
    # ... and the XML carries none either (a guessed type gives 2/3 of the lenses the wrong
    # depth range)
    assert raytrix.read_calib(xml)["lens_types"] == []


def test_a_pitch_hint_the_image_contradicts_is_refused_in_one_line(tmp_path):
    """Issue 21 class 5: --pitch 10.1 on a hex white of 20.2 px wrote a square grid of 11.4 px
    with exit 0."""
    image, _ = white_image((768, 768), pitch_px=20.2, angle_rad=0.05, offset_xy=(384.3, 384.6),
                           seed=1)
    src, out = tmp_path / "white.tif", tmp_path / "g.yaml"
    tifffile.imwrite(src, image)
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--pitch", "10.1"])
    assert res.exit_code == 1 and not out.exists()
    assert res.output.strip().count("\n") == 0
    assert "--pitch 10.1 contradicts the image" in res.output and "hex 20.20" in res.output


def test_a_start_xml_that_is_not_a_lens_array_is_refused(tmp_path):
    from plenocli.io import raytrix
    from plenocli.model.lensgrid import LensGrid

    image, _ = white_image((256, 256), pitch_px=15.0, angle_rad=0.2, offset_xy=(128, 128))
    src, bad, out = tmp_path / "w.tif", tmp_path / "bad.xml", tmp_path / "o.yaml"
    tifffile.imwrite(src, image)
    calib = raytrix.calib_from_grid(LensGrid(15.0, 0.2, (128, 128), image_shape=(256, 256)))
    calib["lens_base_y"] = [0.2588, 0.9659]   # 75 deg from lens_base_x (1, 0)
    calib["lens_base_x"] = [1.0, 0.0]
    raytrix.write_calib(bad, calib)
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "--start", str(bad)])
    assert res.exit_code == 1 and not out.exists()
    assert "not a hexagonal" in res.output and res.output.strip().count("\n") == 0


def test_a_grid_calibrated_on_a_crop_lies_where_the_crop_lay(tmp_path):
    """calibrate records the white's full-sensor origin, so refocus frames the grid on the
    same crop (a grid at origin (0, 0) would be refused there, or land on the wrong pixels)."""
    import json

    from plenocli.io import tiffio

    image, _ = white_image((160, 200), pitch_px=15.3, angle_rad=0.1, offset_xy=(100.3, 80.1),
                           seed=2)
    meta = {tiffio.FORMAT_KEY: tiffio.FORMAT_VERSION, "views": ["raw"], "cfa": None,
            "origin": [40, 60], "active_area": [0, 0, 160, 200], "masked_areas": []}
    src = tmp_path / "white.tif"
    tifffile.imwrite(src, image.astype(np.float32)[None], photometric="minisblack",
                     metadata=None, description=json.dumps(meta))
    out = tmp_path / "g.yaml"
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    assert yaml.safe_load(out.read_text())["lens_grid"]["sensor_origin"] == [40, 60]
    res = CliRunner().invoke(cli, ["refocus", str(src), "--grid", str(out), "-o",
                                   str(tmp_path / "r.tif"), "-q"])
    assert res.exit_code == 0, res.output


def test_a_bayer_mosaic_without_its_pattern_is_refused(tmp_path):
    """A white seen through a Bayer filter (phase gains 0.6, 1, 1, 0.8) but saved as a plain
    mono image: calibrating it as mono would measure the micro-images through the filters."""
    from plenocli.model.cfa import phase_gains

    image, _ = white_image((256, 256), pitch_px=15.3, angle_rad=0.2, offset_xy=(120.3, 130.1),
                           seed=3)
    gains = np.array([[0.6, 1.0], [1.0, 0.8]])
    mosaic = image * np.tile(gains, (128, 128))
    np.testing.assert_allclose(phase_gains(image), 1.0, atol=0.005)
    np.testing.assert_allclose(phase_gains(mosaic), gains / gains.mean(), rtol=0.01)
    src, out = tmp_path / "white.tif", tmp_path / "g.yaml"
    tifffile.imwrite(src, mosaic.astype(np.float32))
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out)])
    assert res.exit_code == 1, res.output
    assert "looks like a 2 x 2 Bayer mosaic" in res.output and "--cfa" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("pitch", [10, 12])
def test_a_mono_white_of_an_even_whole_pixel_pitch_is_no_mosaic(tmp_path, pitch):
    """Audit 18 F1: a mono white whose square lenses sit every ``pitch`` pixels along the pixel
    axes puts every lens at one pixel phase, and its sharp rims leave the four phases 3-7 %
    apart: refused as a hidden Bayer mosaic, with no way through. Its imbalance turns sign
    with the side of the lens (half the blocks either way); a filter's does not."""
    from plenocli.model.cfa import phase_balance

    offset = np.array([256.37, 255.79])
    rows, cols = np.mgrid[0:512, 0:512].astype(float)
    dx = (cols - offset[0] + pitch / 2) % pitch - pitch / 2
    dy = (rows - offset[1] + pitch / 2) % pitch - pitch / 2
    r = np.hypot(dx, dy) / (pitch / 2)
    image = (np.clip(1 - (r / 0.92) ** 8, 0, 1) * np.cos(np.minimum(r, 1) * 1.2) ** 2 * 1000)
    gains, alike = phase_balance(image)
    assert np.abs(gains / gains.mean() - 1).max() > 0.03 and alike.max() < 0.7
    with pytest.raises(InputError, match="looks like a 2 x 2 Bayer mosaic"):   # still refused
        _refuse_hidden_mosaic("w.tif", image * np.tile([[0.7, 1.0], [1.0, 0.9]], (256, 256)))
    src, out = tmp_path / "white.tif", tmp_path / "g.yaml"
    tifffile.imwrite(src, image.astype(np.float32))
    res = CliRunner().invoke(cli, ["calibrate", str(src), "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    lens = yaml.safe_load(out.read_text())["lens_grid"]
    xy = np.array(lens["lenses"]["rows"], float)[:, 2:4]
    assert np.abs((xy - offset + pitch / 2) % pitch - pitch / 2).max() <= 0.1


@pytest.mark.parametrize("se, text", [(4.7267e-05, " (pitch +-0.000047 px)"),
                                      (0.0046, " (pitch +-0.0046 px)"),
                                      (0.0614, " (pitch +-0.061 px)"),
                                      (0.0, ""), (float("inf"), "")])
def test_the_pitch_error_of_a_scene_is_shown_as_measured(se, text):
    # audit 7 E10: a standard error of 4.7e-05 px was printed "+-0.0000 px" (four decimals)
    assert _pitch_error(se) == text


def test_a_dual_pixel_white_is_refused_in_bounded_memory(tmp_path):
    """Audit 10 M1: the decoded frames of a dual-pixel white (two 512 x 784 frames, no
    micro-lenses) led the judge from the pixel grid's aliases to their halves, down to
    0.04 px, whose autocorrelation lags filled 23 GB (killed), or "out of memory" under a
    3 GB limit. No lens lattice is finer than 3 px (candidates.MIN_LENS_PITCH_PX): refused in
    one line, the process far inside 3 GB of address space (measured 0.36 GB resident)."""
    simulate("dualpixel-ghost", tmp_path / "sim", pixels=768)
    frames = tmp_path / "frames.tif"
    assert CliRunner().invoke(cli, ["decode", str(tmp_path / "sim" / "white.dng"), "-o",
                                    str(frames)]).exit_code == 0
    limit = 3 << 30
    done = subprocess.run(
        [str(Path(sys.executable).parent / "plenocli"), "calibrate", str(frames), "-o",
         str(tmp_path / "g.yaml")], capture_output=True, text=True, timeout=300,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)))
    assert done.returncode == 1, done.stderr
    assert "no micro-lens lattice found" in done.stderr and done.stderr.count("\n") == 1
    assert not (tmp_path / "g.yaml").exists()


@pytest.mark.parametrize("shape", [(2000, 3), (3, 2000), (31, 47)])
def test_a_frame_too_small_is_said_so_first_in_columns_x_rows(tmp_path, shape):
    # audit 10 E6: a 3-column frame was told to give --cfa (its pixel phases differ like a
    # mosaic's) where a 3-row one was "too small"; sizes are columns x rows everywhere
    from plenocli.cli.main import cli

    rows, cols = shape
    mosaic = np.tile(np.array([[1.0, 2.0], [2.0, 3.0]], np.float32), (rows, cols))[:rows, :cols]
    tifffile.imwrite(tmp_path / "f.tif", mosaic)
    result = CliRunner().invoke(cli, ["calibrate", str(tmp_path / "f.tif"), "-o",
                                      str(tmp_path / "g.yaml")])
    assert result.exit_code == 1
    assert f"image of {cols} x {rows} px (columns x rows) is too small" in result.output
