"""RayCalibData XML: every real file parses, round-trips, and maps onto the real frame."""

from __future__ import annotations

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
