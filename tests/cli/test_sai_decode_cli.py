"""plenocli sai --grid (approximate S-hat on frames with margins) and plenocli decode --camera
raytrix --calib (the RayCalibData XML kept in the metadata, then used by refocus)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import raytrix, tiffio
from plenocli.io.gridfile import write_grid
from plenocli.model.lensgrid import LensGrid

ROWS, COLS, TOP, LEFT = 40, 50, 4, 6
PITCH, OFFSET = 5.0, (7.3, 6.6)   # square lattice, not a whole number of pixels per lens / 2


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def code(row, col):
    """Each active-area pixel holds its own position, so a view says where it sampled."""
    return np.float32(row * 1000 + col)


def test_sai_with_a_square_grid_samples_the_subaperture_centres(tmp_path):
    frames = np.full((ROWS + TOP + 3, COLS + LEFT + 2), -1.0, np.float32)
    r, c = np.mgrid[0:ROWS, 0:COLS]
    frames[TOP:TOP + ROWS, LEFT:LEFT + COLS] = code(r, c)
    tiffio.write_image(tmp_path / "frames.tif", frames,
                       {"views": ["raw"], "origin": [0, 0],
                        "active_area": [TOP, LEFT, TOP + ROWS, LEFT + COLS]})
    grid = LensGrid(PITCH, 0.0, OFFSET, lattice="square", image_shape=(ROWS, COLS),
                    sensor_origin=(TOP, LEFT))
    write_grid(tmp_path / "grid.yaml", grid, {})
    out = tmp_path / "views.tif"
    result = invoke("sai", tmp_path / "frames.tif", "-n", 2, "--grid", tmp_path / "grid.yaml",
                    "-o", out)
    assert result.exit_code == 0, result.output
    views, meta = tiffio.read_image(out)
    # lens centres inside the 40 x 50 image: x = 2.3 + 5 k (10 of them), y = 1.6 + 5 k (8)
    lens_x, lens_y = 2.3 + PITCH * np.arange(10), 1.6 + PITCH * np.arange(8)
    assert views.shape == (4, 8, 10)
    for i in range(2):
        for j in range(2):   # sub-aperture (i, j) sits (j - 1/2, i - 1/2) * P / 2 off the centre
            cols = np.round(lens_x + (j - 0.5) * PITCH / 2).astype(int)
            rows = np.round(lens_y + (i - 0.5) * PITCH / 2).astype(int)
            np.testing.assert_array_equal(views[2 * i + j], code(rows[:, None], cols[None, :]))
    assert meta["views"] == ["S00", "S01", "S10", "S11"]
    assert meta["sai"]["approximate"] is True
    assert meta["sai"]["crop_sensor_origin"] == [TOP, LEFT]


def test_sai_refuses_a_hex_grid(tmp_path):
    tiffio.write_image(tmp_path / "f.tif", np.zeros((20, 20), np.float32), {"views": ["raw"]})
    write_grid(tmp_path / "hex.yaml", LensGrid(5.0, 0.0, (3.0, 3.0), image_shape=(20, 20)), {})
    result = invoke("sai", tmp_path / "f.tif", "--grid", tmp_path / "hex.yaml",
                    "-o", tmp_path / "v.tif")
    assert result.exit_code == 1
    assert "square lens lattice" in result.output
    assert not (tmp_path / "v.tif").exists()


@pytest.fixture
def raytrix_png(tmp_path):
    rng = np.random.default_rng(5)
    rgb = rng.integers(0, 256, (60, 80, 3), np.uint8)
    cv2.imwrite(str(tmp_path / "frame0.png"), rgb[..., ::-1])  # OpenCV writes BGR
    grid = LensGrid(9.0, 0.0, (40.0, 30.0), image_shape=(60, 80))
    raytrix.write_calib(tmp_path / "calib.xml", raytrix.calib_from_grid(grid))
    return tmp_path, rgb


def test_decode_raytrix_keeps_the_calibration(raytrix_png, tmp_path):
    """A calibration the frames check is kept; on frames that show no lattice (noise here,
    the R42 crop) none can be checked, and another camera's passed unseen (audit 24a W4)."""
    from plenocli.pipeline.stages.simulate import simulate

    folder, _ = raytrix_png
    result = invoke("decode", folder / "frame0.png", "--camera", "raytrix",
                    "--calib", folder / "calib.xml", "-o", folder / "noise.tif")
    assert result.exit_code == 1 and "show no micro-image lattice to check it" in result.stderr
    assert not (folder / "noise.tif").exists()
    simulate("hexgrid-white", tmp_path / "w", seed=2)
    white, xml, out = (tmp_path / "w" / n for n in ("white.tif", "grid_true.xml", "f.tif"))
    result = invoke("decode", white, "--camera", "raytrix", "--calib", xml, "-o", out)
    assert result.exit_code == 0, result.output
    frames, meta = tiffio.read_image(out)
    assert meta["camera"] == "raytrix"
    assert meta["raytrix_calib"] == raytrix.read_calib(xml)
    roles = {item["role"] for item in meta["provenance"]["inputs"]}
    assert {"input", "calib"} <= roles


def test_decode_raytrix_without_calib_fails_cleanly(raytrix_png):
    folder, _ = raytrix_png
    result = invoke("decode", folder / "frame0.png", "--camera", "raytrix",
                    "-o", folder / "frames.tif")
    assert result.exit_code == 1
    assert "needs the RayCalibData XML" in result.output
    assert not (folder / "frames.tif").exists()


def test_sai_with_a_grid_refuses_a_bayer_mosaic(tmp_path):
    """audit 7 W9: with a pitch that is not N pixels, the pixel nearest a sub-aperture centre
    falls on R in one lens and G in the next; the views were labelled one colour each."""
    frames = np.random.default_rng(1).random((ROWS, COLS)).astype(np.float32)
    tiffio.write_image(tmp_path / "frames.tif", frames, {"views": ["raw"], "cfa": "RGGB"})
    grid = LensGrid(PITCH, 0.0, OFFSET, lattice="square", image_shape=(ROWS, COLS))
    write_grid(tmp_path / "grid.yaml", grid, {})
    result = invoke("sai", tmp_path / "frames.tif", "-n", 2, "--grid", tmp_path / "grid.yaml",
                    "-o", tmp_path / "views.tif")
    assert result.exit_code == 1 and "would mix colours" in result.stderr, result.output
    assert not (tmp_path / "views.tif").exists()


def test_decode_raytrix_refuses_another_cameras_calibration(tmp_path):
    """audit 7 P4: the RayCalibData was stored unchecked, so the frames' metadata could describe
    another camera (diameter 70 px on frames of 23.2 px lenses); it is checked as refocus --grid
    checks a grid."""
    from plenocli.pipeline.stages.simulate import simulate

    simulate("hexgrid-white", tmp_path / "w", seed=2)
    calib = raytrix.read_calib(tmp_path / "w" / "grid_true.xml")
    raytrix.write_calib(tmp_path / "other.xml", {**calib, "diameter": calib["diameter"] * 1.1})
    white = tmp_path / "w" / "white.tif"
    result = invoke("decode", white, "--camera", "raytrix", "--calib", tmp_path / "other.xml",
                    "-o", tmp_path / "bad.tif")
    assert result.exit_code == 1 and "does not fit the frames" in result.stderr, result.output
    assert not (tmp_path / "bad.tif").exists()
    result = invoke("decode", white, "--camera", "raytrix", "--calib",
                    tmp_path / "w" / "grid_true.xml", "-o", tmp_path / "good.tif")
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("crop, refused", [("60x60", True), ("56x56", False)])
def test_sai_after_a_central_crop_names_the_views_right_or_refuses(tmp_path, crop, refused):
    """audit 19 W4: bias --crop 60x60 of a 64 x 64 frame of 4 x 4 micro-images starts 2 pixels
    into one: sai named sub-aperture (2, 2) S00, and every other view after another's, exit 0."""
    import tifffile

    yy, xx = np.mgrid[:64, :64]
    tifffile.imwrite(tmp_path / "q.tif", (100 + (yy % 4) * 10 + xx % 4).astype(np.uint16),
                     photometric="minisblack")
    run = CliRunner().invoke
    assert run(cli, ["decode", str(tmp_path / "q.tif"), "--black", "50", "--cfa", "RGGB",
                     "-o", str(tmp_path / "f.tif")]).exit_code == 0
    assert run(cli, ["bias", str(tmp_path / "f.tif"), "--overscan", "none", "--crop", crop,
                     "-o", str(tmp_path / "b.tif")]).exit_code == 0
    result = run(cli, ["sai", str(tmp_path / "b.tif"), "-n", "4", "-o", str(tmp_path / "s.tif")])
    if refused:
        assert result.exit_code == 1 and "2 row(s) and 2 column(s) into" in result.output
        assert not (tmp_path / "s.tif").exists()
    else:
        assert result.exit_code == 0, result.output
        views, _ = tiffio.read_image(tmp_path / "s.tif")
        assert np.array_equal(views[:, 0, 0], [50 + 10 * i + j for i in range(4) for j in range(4)])
