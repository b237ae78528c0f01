"""plenocli crosstalk end to end: masked captures, and the Raytrix mask-width sweep with a YAML
grid or the camera's RayCalibData XML (placed on the frames' active area, as refocus does)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import raytrix, tiffio
from plenocli.io.gridfile import write_grid
from plenocli.model.lensgrid import LensGrid

R_TRUE = 0.125          # light leaking into the masked pupil half
ROWS, COLS = 150, 200   # active area
TOP, LEFT = 6, 10       # over-scan margins before it
GRID = LensGrid(pitch_px=14.0, angle_rad=0.0, offset_xy=(100.3, 75.6),
                image_shape=(ROWS, COLS))


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def half_masked_white() -> np.ndarray:
    """A white target behind a pupil whose right half is masked: in every micro-image the
    pixels left of the lens centre see 1, those right of it R_TRUE (the leak)."""
    y, x = np.mgrid[0:ROWS, 0:COLS].astype(float)
    i, j = GRID.nearest_index(x, y)
    centre_x = GRID.lattice_xy(i, j)[..., 0]
    return np.where(x < centre_x, 1.0, R_TRUE).astype(np.float32)


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    folder = tmp_path_factory.mktemp("masked")
    frame = np.zeros((ROWS + TOP + 4, COLS + LEFT + 2), np.float32)
    frame[TOP:TOP + ROWS, LEFT:LEFT + COLS] = half_masked_white()
    tiffio.write_image(folder / "frames.tif", frame,
                       {"views": ["raw"], "cfa": None, "origin": [0, 0],
                        "active_area": [TOP, LEFT, TOP + ROWS, LEFT + COLS]})
    write_grid(folder / "grid.yaml", LensGrid(GRID.pitch_px, GRID.angle_rad, GRID.offset_xy,
                                               image_shape=GRID.image_shape,
                                               sensor_origin=(TOP, LEFT)), {})
    raytrix.write_calib(folder / "calib.xml", raytrix.calib_from_grid(GRID))
    return folder


@pytest.mark.parametrize("grid_name", ["grid.yaml", "calib.xml"])
def test_mask_width_sweep_recovers_the_leak(capture, tmp_path, grid_name):
    out = tmp_path / "sweep.json"
    result = invoke("crosstalk", capture / "frames.tif", "--mask-widths", "0,2",
                    "--grid", capture / grid_name, "--s", 0.5, "--g", 1, "--tile", 8,
                    "--intended", "left", "-o", out)
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    assert [row["mask_width"] for row in doc["sweep"]] == [0.0, 2.0]
    for row in doc["sweep"]:
        assert row["r"] == pytest.approx(R_TRUE, abs=1e-4)
        assert row["flux_intended"] == pytest.approx(1.0, abs=1e-4)
    assert doc["provenance"]["stage"] == "crosstalk"


def test_mask_width_sweep_refuses_the_wrong_open_half(capture, tmp_path):
    """audit 9 W6: the sweep vouched r = 1169 % for --intended naming the masked half; as every
    measurement of a masked white, the open half must be the brighter one everywhere."""
    out = tmp_path / "sweep.json"
    result = invoke("crosstalk", capture / "frames.tif", "--mask-widths", "0,2",
                    "--grid", capture / "grid.yaml", "--s", 0.5, "--g", 1, "--tile", 8,
                    "--intended", "right", "-o", out)
    assert result.exit_code == 1, result.output
    assert "the open part right is not brighter than the others" in result.output
    assert "mask width 0 px" in result.output and "check --intended" in result.output
    assert not out.exists()


def test_refocus_and_crosstalk_frame_an_xml_grid_alike(capture, tmp_path):
    """refocus --grid calib.xml and the sweep's left view are the same image."""
    args = ("--grid", capture / "calib.xml", "--s", 0.5, "--g", 1)
    assert invoke("refocus", capture / "frames.tif", *args, "--view", "left",
                  "--mask-width", 0, "-o", tmp_path / "left.tif").exit_code == 0
    left, meta = tiffio.read_image(tmp_path / "left.tif")
    assert meta["refocus"]["crop_sensor_origin"] == [TOP, LEFT]
    finite = np.isfinite(left)
    assert finite.mean() > 0.5  # g = 1: the left half-pixels cover part of the output
    np.testing.assert_allclose(left[finite], 1.0, atol=1e-5)


def test_sweep_needs_a_grid(capture, tmp_path):
    result = invoke("crosstalk", capture / "frames.tif", "--mask-widths", "0,1",
                    "-o", tmp_path / "x.json")
    assert result.exit_code == 2  # a usage error, before any work (audit 7 E17)
    assert "--mask-widths needs --grid" in result.output
    assert not (tmp_path / "x.json").exists()


def test_masked_views_report_and_heat_map(tmp_path):
    """Two views with a known ratio: the report holds it, the preview is a PNG."""
    rng = np.random.default_rng(3)
    main = rng.uniform(900, 1100, (64, 96)).astype(np.float32)
    views = np.stack([main, 0.2 * main])
    tiffio.write_image(tmp_path / "views.tif", views, {"views": ["A", "B"]})
    out, png = tmp_path / "r.json", tmp_path / "r.png"
    result = invoke("crosstalk", tmp_path / "views.tif", "--tile", 16, "-o", out,
                    "--preview", png)
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    assert doc["r"] == pytest.approx(0.2, rel=1e-6)
    assert doc["captures"][0]["intended"] == "A"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_colour_pages_and_a_sum_view_are_not_other_views(tmp_path):
    """r compares pupil parts: the colour pages of one view are one view, and a dual-pixel
    file's S = A + B is left out by default (refused when named)."""
    cast = np.array([0.5, 1.0, 0.7], np.float32)[:, None, None]
    pages = np.ones((6, 64, 64), np.float32)
    pages[:3] *= 1000 * cast   # A open
    pages[3:] *= 100 * cast    # B: 10 % cross-talk
    tiffio.write_image(tmp_path / "rgb.tif", pages, {"views": ["A.R", "A.G", "A.B", "B.R", "B.G",
                                                        "B.B"], "cfa": None})
    frames = np.ones((3, 64, 64), np.float32) * np.array([900, 100, 1000], np.float32)[:, None,
                                                                                      None]
    tiffio.write_image(tmp_path / "dp.tif", frames, {"views": ["A", "B", "S"], "cfa": None})
    for name, r in (("rgb", 0.1), ("dp", 100 / 900)):
        result = CliRunner().invoke(cli, ["crosstalk", str(tmp_path / f"{name}.tif"), "-o",
                                          str(tmp_path / f"{name}.json")])
        assert result.exit_code == 0, result.output
        assert json.loads((tmp_path / f"{name}.json").read_text())["r"] == pytest.approx(r)
    result = CliRunner().invoke(cli, ["crosstalk", str(tmp_path / "dp.tif"), "--views", "A,B,S",
                                      "-o", str(tmp_path / "x.json")])
    assert result.exit_code == 1 and "sum A + B" in result.output
