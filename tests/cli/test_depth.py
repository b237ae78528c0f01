"""`plenocli depth` and `refocus --depth` end to end, including bad input."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.pipeline.stages.simulate import simulate


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def lenslet(tmp_path_factory):
    out = tmp_path_factory.mktemp("lenslet")
    simulate("lenslet-depth", out, seed=4, pixels="300x400", scene="plane", g=4.5)
    return out


def test_depth_lies_on_the_refocus_grid_and_feeds_all_in_focus(lenslet, tmp_path):
    depth, png, aif, ref = (tmp_path / n for n in ("d.tif", "d.png", "aif.tif", "r.tif"))
    result = invoke("depth", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml",
                    "-o", depth, "--preview", png)
    assert result.exit_code == 0, result.output
    data, meta = tiffio.read_image(depth)
    assert meta["views"] == ["g", "confidence"] and png.exists()
    truth, _ = tiffio.read_image(lenslet / "depth.tif")
    assert invoke("refocus", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml",
                  "-o", ref).exit_code == 0
    image, _ = tiffio.read_image(ref)
    assert data.shape[1:] == image.shape[1:] == truth.shape[1:]
    inner = np.isfinite(data[0])
    inner[:6], inner[-6:], inner[:, :6], inner[:, -6:] = False, False, False, False
    assert np.median(np.abs(data[0][inner] - 4.5)) <= 0.1
    result = invoke("refocus", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml",
                    "--depth", depth, "-o", aif)
    assert result.exit_code == 0, result.output
    assert tiffio.read_meta(aif)["provenance"]["parameters"]["depth"] == str(depth)


def test_dual_pixel_views_give_disparity(tmp_path):
    simulate("dualpixel-depth", tmp_path / "sim", seed=2, pixels="96x256",
             disparities=(-1.0,) * 4 + (1.0,) * 4)
    out = tmp_path / "d.tif"
    result = invoke("depth", tmp_path / "sim" / "views.tif", "-o", out)
    assert result.exit_code == 0, result.output
    data, meta = tiffio.read_image(out)
    assert meta["views"] == ["disparity", "confidence"]
    assert abs(np.median(data[0][20:-20, 20:100]) + 1.0) < 0.1
    assert abs(np.median(data[0][20:-20, 156:236]) - 1.0) < 0.1


def test_bad_input_is_refused_in_one_line(lenslet, tmp_path):
    out = tmp_path / "d.tif"
    result = invoke("depth", lenslet / "frames.tif", "-o", out)  # frames without --grid
    assert result.exit_code == 1 and "--grid" in result.output and not out.exists()
    result = invoke("depth", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml",
                    "--g", "0.5:3", "-o", out)
    assert result.exit_code == 2 and not out.exists()
    result = invoke("refocus", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml",
                    "--depth", lenslet / "depth.tif", "--s", 0.25, "-o", out)
    assert result.exit_code == 1 and "same --grid and --s" in result.output
    assert not out.exists()


def test_metric_depth_on_the_simulated_camera(tmp_path):
    truth = simulate("lenslet-depth", tmp_path / "sim", seed=6, pixels="300x400",
                     scene="plane", distance_m=0.9)
    camera = tmp_path / "camera.yaml"
    camera.write_text("".join(f"{k}: {v}\n" for k, v in truth["camera"].items()))
    out = tmp_path / "d.tif"
    result = invoke("depth", tmp_path / "sim" / "frames.tif", "--grid",
                    tmp_path / "sim" / "grid.yaml", "--camera", camera, "-o", out)
    assert result.exit_code == 0, result.output
    data, meta = tiffio.read_image(out)
    assert meta["views"] == ["g", "depth_m", "confidence"]
    assert abs(np.nanmedian(data[1][8:-8, 8:-8]) - 0.9) < 0.005  # 0.5 %
    camera.write_text("focal_length_mm: 50\nfocus_distance_m: -2\nmla_sensor_mm: 0.4\n")
    other = tmp_path / "e.tif"
    result = invoke("depth", tmp_path / "sim" / "frames.tif", "--grid",
                    tmp_path / "sim" / "grid.yaml", "--camera", camera, "-o", other)
    assert result.exit_code == 1 and "focus_distance_m" in result.output
    assert not other.exists()


def test_more_refusals_leave_nothing(lenslet, tmp_path):
    out = tmp_path / "x.tif"
    other = tmp_path / "frames_copy.tif"  # frames given as a depth map: another file
    other.write_bytes((lenslet / "frames.tif").read_bytes())
    cases = [
        (["depth", lenslet / "depth.tif", "-o", out], 1, "dual-pixel views A, B"),
        (["depth", lenslet / "frames.tif", "--camera", lenslet / "grid.yaml", "-o", out], 1,
         "needs lenslet frames and --grid"),
        (["refocus", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml", "--depth",
          other, "-o", out], 1, "no page g"),
        (["refocus", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml", "--depth",
          lenslet / "frames.tif", "-o", out], 1, "give each its own file"),
        (["refocus", lenslet / "frames.tif", "--grid", lenslet / "grid.yaml", "--depth",
          lenslet / "depth.tif", "--g", "2,3", "-o", out], 1, "not a sweep"),
    ]
    for args, code, words in cases:
        result = invoke(*args)
        assert result.exit_code == code and words in result.output, (args, result.output)
        assert len(result.output.strip().splitlines()) == 1 and not out.exists()


def test_bayer_frames_of_the_refocus_simulator(tmp_path):
    """The refocus simulator's own plane (another renderer), as a GBRG mosaic."""
    simulate("raytrix-scene", tmp_path / "sim", seed=3, rows=240, cols=320, cfa="GBRG",
             g_true=4.5)
    out = tmp_path / "d.tif"
    result = invoke("depth", tmp_path / "sim" / "frames.tif", "--grid",
                    tmp_path / "sim" / "grid.yaml", "-o", out)
    assert result.exit_code == 0, result.output
    data, _ = tiffio.read_image(out)
    assert abs(np.nanmedian(data[0][6:-6, 6:-6]) - 4.5) <= 0.03  # measured 0.007 at 480 x 640
