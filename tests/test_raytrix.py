"""RayCalibData XML: every real file parses, round-trips, and maps onto the real frame."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli import calibration
from plenocli.errors import InputError
from plenocli.io import gridfile, raytrix
from plenocli.model.lensgrid import LensGrid


def _xmls(realdata):
    return sorted((realdata / "raytrix").rglob("*.xml"))


@pytest.mark.realdata
def test_every_real_file_parses_and_round_trips(realdata):
    for path in _xmls(realdata):
        if path.name == "Boys__calib.xml":
            with pytest.raises(InputError, match="TSPCCalibData"):
                raytrix.read_calib(path)
            continue
        calib = raytrix.read_calib(path)
        again = raytrix.parse_calib(raytrix.format_calib(calib))
        assert again == calib, path.name
        assert calib["diameter"] > 0 and len(calib["lens_types"]) == 3


@pytest.mark.parametrize("text", ["<RayCalibData><offset>", "not xml at all",
                                  "<RayCalibData version='1.0'><diameter>5</diameter>"
                                  "</RayCalibData>"])
def test_malformed_xml_is_an_input_error(text):
    with pytest.raises(InputError):
        raytrix.parse_calib(text)


@pytest.mark.parametrize("angle", [0.0, 0.3, -1.2, 2.9])
def test_grid_calib_grid_round_trip(angle):
    grid = LensGrid(23.2, angle, (1001.3, 1040.8), image_shape=(2048, 2000))
    back = raytrix.grid_from_calib(raytrix.calib_from_grid(grid), (2048, 2000))
    same = calibration.compare_grids(grid, back, (2048, 2000))
    assert same["max_px"] < 1e-6
    assert back.pitch_px == pytest.approx(23.2)


def test_offset_convention_centre_and_y_up():
    calib = raytrix.calib_from_grid(LensGrid(20.0, 0.0, (505.0, 495.0), image_shape=(1000, 1000)))
    assert calib["offset"] == pytest.approx([5.0, 5.0])   # x right of centre, y up (above)


@pytest.mark.realdata
def test_read_grid_accepts_xml(realdata):
    path = realdata / "raytrix" / "origami" / "calib.xml"
    with pytest.raises(InputError, match="image size"):
        gridfile.read_grid(path)
    grid = gridfile.read_grid(path, image_shape=(2048, 2048))
    assert grid.pitch_px == pytest.approx(23.202295303345)
    # offset from the centre, y up: x = W/2 + 13.04, y = H/2 + 20.35
    assert grid.offset_xy == pytest.approx((1024 + 13.040943844572, 1024 + 20.348051920159))


@pytest.mark.parametrize("angle", [0.0, -np.pi / 2, np.pi / 3, 0.3])
@pytest.mark.parametrize("types", [(0, 1, 2), (2, 0, 1), (1, 2, 0)])
def test_lens_types_round_trip(angle, types):
    """Written types are read back on the same lenses."""
    grid = LensGrid(23.2, angle, (1001.3, 1040.8), image_shape=(2048, 2000),
                    lens_type_of_coset=types)
    back = raytrix.grid_from_calib(raytrix.parse_calib(raytrix.format_calib(
        raytrix.calib_from_grid(grid))), (2048, 2000))
    i, j = np.meshgrid(np.arange(-4, 5), np.arange(-4, 5))
    x, y = grid.lattice_xy(i.ravel(), j.ravel()).T
    assert np.array_equal(back.lens_types(*back.nearest_index(x, y)),
                          grid.lens_types(i.ravel(), j.ravel()))


def test_no_types_written_when_none_measured():
    grid = LensGrid(23.2, 0.1, (1001.3, 1040.8), image_shape=(2048, 2000))
    assert raytrix.calib_from_grid(grid)["lens_types"] == []


def _calib(base_x, base_y, type1):
    return {"diameter": 20.0, "offset": [0.0, 0.0], "lens_base_x": base_x,
            "rotation": float(np.arctan2(base_x[1], base_x[0])),
            "lens_base_y": base_y, "lens_types": [
                {"id": 0, "offset": [0.0, 0.0], "depth_range": [1, 3]},
                {"id": 1, "offset": type1, "depth_range": [2.8, 4]},
                {"id": 2, "offset": [-v for v in type1], "depth_range": [3.8, 100]}]}


def test_type_t_sits_at_minus_its_offset():
    # Fujita2's layout: base_x up; type 1, written at base_x's numbers, is the lens BELOW
    calib = _calib([0.0, 1.0], [0.8660254, 0.5], [0.0, 1.0])
    grid = raytrix.grid_from_calib(calib, (400, 400))
    assert grid.lens_types(*grid.nearest_index(200.0, 220.0)) == 1
    assert grid.lens_types(*grid.nearest_index(200.0, 180.0)) == 2
    # the R42's: base_x right; type 1 is the lens on the LEFT
    calib = _calib([1.0, 0.0], [0.5, -0.8660254], [1.0, 0.0])
    grid = raytrix.grid_from_calib(calib, (400, 400))
    assert grid.lens_types(*grid.nearest_index(180.0, 200.0)) == 1
    assert grid.lens_types(*grid.nearest_index(220.0, 200.0)) == 2


def _type_sharpness(image, grid, types_from):
    """(g, relative sharpness, the start's type) of the lenses of ``grid`` with all six
    neighbours: each lens's detail against its neighbours' (the scene cancels)."""
    from plenocli.calibration.lenstypes import (
        lens_sharpness,
        lens_virtual_depth,
        local_contrast,
    )

    flat = calibration.flatten(image, scale_px=1.5 * grid.pitch_px)
    rows, local = local_contrast(grid.indices, lens_sharpness(flat, grid.centres_xy,
                                                              grid.pitch_px))
    g = lens_virtual_depth(flat, grid.indices, grid.centres_xy, grid.pitch_px)[rows]
    return g, local, types_from.lens_types(*types_from.nearest_index(*grid.centres_xy[rows].T))


def _image(folder, name):
    import cv2

    return cv2.imread(str(folder / name))[..., :3].astype(np.float32).sum(-1)


@pytest.mark.realdata
def test_xml_types_are_the_cosets_sharpest_in_their_depth_ranges(realdata):
    """Fujita2 with its own XML (type t at minus its offset): the type-2 lenses (range
    3.5-100) are the sharpest (relative to their neighbours) in the far third of the frame's
    g and gain most from the near third to it, type 0 (1-3.2) loses most. Read the other way,
    types 1 and 2 swap (measured near / far: type 0 +0.06 / -0.26, type 1 +0.17 / +0.04,
    type 2 +0.01 / +0.26)."""
    folder = realdata / "raytrix" / "fujita2"
    image = _image(folder, "frame0.png")
    grid, _ = calibration.calibrate(image)
    xml = gridfile.read_grid(folder / "calib.xml", image_shape=image.shape)
    assert xml.lens_type_of_coset is not None
    g, local, types = _type_sharpness(image, grid, xml)
    low, high = np.nanpercentile(g, (100 / 3, 200 / 3))
    near = [np.median(local[(types == t) & (g <= low)]) for t in range(3)]
    far = [np.median(local[(types == t) & (g >= high)]) for t in range(3)]
    change = np.subtract(far, near)
    assert int(np.argmax(far)) == 2 and list(np.argsort(change)) == [0, 1, 2], (near, far)


@pytest.mark.realdata
def test_r42_xml_types_follow_their_depth_ranges(realdata):
    """The R42 crop (another camera, base_x right instead of up) with the grid its XML gives
    (`calibrate --start`, types kept): every lens sees g 5.2-7.1, beyond type 1's range
    (2.8-4) and in type 2's (3.8-100): type 2 is the sharpest, type 0 (1-3) the least
    (measured +0.25, +0.03, -0.27)."""
    folder = realdata / "raytrix" / "r42_crop"
    image = _image(folder, "sc2_klein.png")
    xml = gridfile.read_grid(folder / "sc2_klein.xml", image_shape=image.shape)
    grid, report = calibration.calibrate(image, start=xml)
    assert report.lens_types["source"] == "the start file"
    g, local, types = _type_sharpness(image, grid, grid)
    assert np.nanpercentile(g, 10) > 4.5
    order = [np.median(local[types == t]) for t in range(3)]
    assert order[2] > order[1] > order[0], order

def _xml(**changes) -> str:
    grid = LensGrid(23.2, 0.3, (1001.3, 1040.8), image_shape=(2048, 2000))
    return raytrix.format_calib({**raytrix.calib_from_grid(grid), **changes})


def test_a_rotation_in_degrees_is_converted_and_lengths_in_other_units_refused():
    text = _xml()
    rad = raytrix.parse_calib(text)["rotation"]
    deg = text.replace(f'<rotation units="rad">{rad!r}',
                       f'<rotation units="deg">{rad * 180 / 3.141592653589793!r}')
    assert raytrix.parse_calib(deg)["rotation"] == pytest.approx(rad, abs=1e-12)
    for tag in ("diameter", "offset", "lens_border"):
        with pytest.raises(InputError, match=f'<{tag} units="mm">: plenocli reads {tag} in pix'):
            raytrix.parse_calib(text.replace(f'<{tag} units="pix">', f'<{tag} units="mm">', 1))


@pytest.mark.parametrize("old, new, words", [
    ("</diameter>", "</diameter><diameter>40.0</diameter>", "<diameter> is given 2 times"),
    ("</x>", "</x><x>7</x>", "<offset/x> is given 2 times"),
    ("<function>", "<function>Brown</function><function>", "<distortion/function> is given 2"),
])
def test_an_element_given_twice_is_refused(old, new, words):
    with pytest.raises(InputError, match=words):
        raytrix.parse_calib(_xml().replace(old, new, 1))


@pytest.mark.parametrize("distortion, words", [
    ({"function": "Brown", "parameters": [-0.0015, 0.0007]}, "distortion .Brown -0.0015"),
    ({"function": "spline9", "parameters": []}, "function 'spline9' is not one"),
])
def test_a_distortion_plenocli_does_not_apply_is_refused_not_dropped(distortion, words):
    calib = raytrix.parse_calib(_xml(distortion={"type": "radial", "offset": [0.0, 0.0],
                                                 **distortion}))
    with pytest.raises(ValueError, match=words):
        raytrix.grid_from_calib(calib, (2048, 2000))
    none = {**calib["distortion"], "function": "Brown", "parameters": [0.0, 0.0]}
    assert raytrix.grid_from_calib({**calib, "distortion": none}, (2048, 2000)).pitch_px == 23.2


def test_distortion_parameters_must_be_as_many_as_counted():
    text = _xml().replace('<parameter count="0">0</parameter>',
                          '<parameter count="0">0.3;0.1</parameter>')
    with pytest.raises(InputError, match="count 0 but holds 2 values"):
        raytrix.parse_calib(text)
