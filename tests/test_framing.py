"""plenocli.io.framing: active areas, CFA phases, grids framed on frames with margins."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.errors import InputError
from plenocli.io import raytrix
from plenocli.io.framing import active_area, frame_grid, grid_framing, load_grid, sensor_image
from plenocli.io.gridfile import write_grid
from plenocli.model.lensgrid import LensGrid

META = {"origin": [100, 200], "active_area": [3, 5, 43, 65], "cfa": "RGGB", "views": ["raw"]}
SHAPE = (50, 70)


def test_active_area_crops_and_shifts_the_cfa_phase():
    framing = active_area(META, SHAPE)
    assert (framing.top, framing.left, framing.bottom, framing.right) == (3, 5, 43, 65)
    assert framing.shape == (40, 60)
    assert framing.cfa == "BGGR"  # odd row and column: the pattern seen from (1, 1)
    assert framing.sensor_origin == (103, 205)
    pages = np.arange(2 * 50 * 70).reshape(2, 50, 70)
    np.testing.assert_array_equal(framing.crop(pages), pages[:, 3:43, 5:65])


def test_no_active_area_is_the_whole_page():
    framing = active_area({}, SHAPE)
    assert (framing.top, framing.left, framing.bottom, framing.right) == (0, 0, 50, 70)
    assert framing.cfa is None and framing.sensor_origin == (0, 0) and framing.grid is None


def test_grid_is_expressed_in_the_crop():
    grid = LensGrid(10.0, 0.1, (20.5, 15.25), image_shape=(30, 40), sensor_origin=(108, 210))
    framing = grid_framing(META, SHAPE, grid)
    assert (framing.top, framing.left, framing.bottom, framing.right) == (8, 10, 38, 50)
    assert framing.grid.offset_xy == pytest.approx((20.5, 15.25))  # same pixel, new origin
    assert framing.grid.sensor_origin == (108, 210) == framing.sensor_origin
    assert framing.cfa == "RGGB"


def test_grid_without_size_covers_the_active_area():
    grid = LensGrid(10.0, 0.0, (30.0, 20.0), sensor_origin=(100, 200))  # the file's pixels
    framing = grid_framing(META, SHAPE, grid)
    assert framing.shape == (40, 60)
    assert framing.grid.offset_xy == pytest.approx((25.0, 17.0))


def test_grid_outside_the_frames_is_refused():
    grid = LensGrid(10.0, 0.0, (5.0, 5.0), image_shape=(60, 40), sensor_origin=(100, 200))
    with pytest.raises(InputError, match="calibrated on a 40 x 60 image"):
        grid_framing(META, SHAPE, grid, frames_path="f.tif", grid_path="g.yaml")


@pytest.mark.parametrize("origin", [(100, 200), (100, 205), (103, 200)])
def test_grid_over_masked_pixels_is_refused(origin):
    """Inside the page but over masked rows or columns, which hold no micro-images: the grid
    was calibrated on another image, not on these frames' white."""
    grid = LensGrid(10.0, 0.0, (5.0, 5.0), image_shape=(40, 60), sensor_origin=origin)
    with pytest.raises(InputError, match=r"active area of f.tif is 60 x 40 at \(103, 205\)"):
        grid_framing(META, SHAPE, grid, frames_path="f.tif", grid_path="g.yaml")
    on_area = grid_framing(META, SHAPE, LensGrid(10.0, 0.0, (5.0, 5.0), image_shape=(40, 60),
                                                 sensor_origin=(103, 205)))
    assert (on_area.top, on_area.left, on_area.bottom, on_area.right) == (3, 5, 43, 65)


def test_xml_grid_is_placed_on_the_active_area(tmp_path):
    on_area = LensGrid(9.5, 0.0, (31.0, 19.0), image_shape=(40, 60))
    raytrix.write_calib(tmp_path / "calib.xml", raytrix.calib_from_grid(on_area))
    grid = load_grid(tmp_path / "calib.xml", META, SHAPE)
    assert grid.image_shape == (40, 60) and grid.sensor_origin == (103, 205)
    framing = frame_grid(tmp_path / "calib.xml", META, SHAPE)
    assert (framing.top, framing.left) == (3, 5)
    i, j = framing.grid.nearest_index(31.0, 19.0)
    assert framing.grid.lattice_xy(i, j) == pytest.approx((31.0, 19.0), abs=1e-6)


def test_yaml_grid_keeps_its_own_placement(tmp_path):
    grid = LensGrid(10.0, 0.0, (5.0, 5.0), image_shape=(20, 20), sensor_origin=(110, 220))
    write_grid(tmp_path / "g.yaml", grid, {})
    framing = frame_grid(tmp_path / "g.yaml", META, SHAPE)
    assert (framing.top, framing.left, framing.bottom, framing.right) == (10, 20, 30, 40)


def test_sensor_image_averages_colour_pages_only():
    pages = np.stack([np.full((2, 3), v, np.uint8) for v in (30, 60, 90)])
    assert sensor_image(pages, {"views": ["R", "G", "B"]}).tolist() == [[60.0] * 3] * 2
    first = sensor_image(pages, {"views": ["S", "A", "B"]})
    assert first.dtype == np.float32 and first.tolist() == [[30.0] * 3] * 2
