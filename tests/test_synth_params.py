"""The simulated kinds' parameters are declared once (plenocli.synth.params): every parameter a
generator takes has a meaning and a range, and values outside it are refused by name."""

from __future__ import annotations

import inspect
import re

import pytest

from plenocli.pipeline.schema.simulate import PARAMS as OPTIONS
from plenocli.synth import KIND_NAMES, generator
from plenocli.synth.params import PARAMS, Param, check_params


def test_every_generator_parameter_is_declared():
    missing = {(kind, name) for kind in KIND_NAMES
               for name in inspect.signature(generator(kind)).parameters if name not in PARAMS}
    assert not missing, missing


@pytest.mark.parametrize("kind, params, words", [
    ("dualpixel", {"noise": -5.0}, "noise must be in [0, 65535] (read noise, DN"),
    ("dualpixel-prism", {"crosstalk": 1.0}, "crosstalk must be in [0, 1)"),
    ("raytrix-scene", {"s": 0.0}, "s must be in (0, 1]"),
    ("stereo-rig", {"view_shape": [200, 8]}, "view_shape must be >= 32"),
    ("dualpixel", {"seed": -1}, "seed must be in [0, 4294967296)"),
    ("dualpixel", {"noise": "loud"}, "noise = 'loud' is not a finite number (its default is 2.0)"),
    ("hexgrid-white", {"size": "0x64"},
     "size = '0x64' is not a whole number (its default is 1024)"),
    ("dualpixel", {"rays": 2}, "simulate dualpixel does not take 'rays'"),
])
def test_values_out_of_range_are_refused_by_name(kind, params, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        check_params(kind, generator(kind), params)


@pytest.mark.parametrize("kind, params, words", [
    # audit 9 E1: g of the steps scene, and g beside distance_m, were recorded and ignored
    ("lenslet-depth", {"g": 2.5}, "g = 2.5 is not used: only the plane scene is placed by g"),
    ("lenslet-depth", {"scene": "plane", "g": 4.0, "distance_m": 0.9},
     "g = 4.0 is not used: distance_m = 0.9 places the plane"),
    ("lenslet-depth", {"scene": "slanted", "distance_m": 0.9},
     "distance_m = 0.9 is not used: distance_m places the plane scene (scene is 'slanted')"),
    ("dualpixel-white", {"prism_apex_deg": 20.0}, "prism_apex_deg = 20.0 is not used"),
    ("dualpixel-prism", {"no_prisms": True, "prism_apex_deg": 20.0}, "the prisms are left out"),
])
def test_a_parameter_the_other_values_leave_unused_is_refused(kind, params, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        check_params(kind, generator(kind), params)


@pytest.mark.parametrize("kind, params", [
    ("lenslet-depth", {"scene": "plane", "g": 2.5}),
    ("lenslet-depth", {"scene": "plane", "distance_m": 0.9}),
    ("dualpixel-prism", {"prism_apex_deg": 20.0}),
])
def test_a_parameter_its_kind_uses_is_taken(kind, params):
    assert check_params(kind, generator(kind), params) == params


def test_rows_x_cols_for_a_square_only_kind_says_so_and_help_names_the_kinds_that_take_it():
    # audit 7 E4: --help promised ROWSxCOLS; quadpixel-pyramid said "not a value like its
    # default 256"
    with pytest.raises(ValueError, match=re.escape("pixels = '240x320': this kind's sensor is "
                                                   "square; give one number, e.g. 256")):
        check_params("quadpixel-pyramid", generator("quadpixel-pyramid"), {"pixels": "240x320"})
    rectangular = []
    for kind in KIND_NAMES:
        pixels = inspect.signature(generator(kind)).parameters.get("pixels")
        if pixels is not None and not isinstance(pixels.default, int):
            check_params(kind, generator(kind), {"pixels": "64x96"})
            rectangular.append(kind)
    said = next(p.help for p in OPTIONS if p.name == "pixels")
    assert "dualpixel and the -depth kinds" in said
    assert rectangular and all(k == "dualpixel" or k.endswith("-depth") for k in rectangular)
    assert {k for k in KIND_NAMES if k.endswith("-depth")} <= set(rectangular)


def test_the_ends_of_a_range():
    fraction = Param("r", 0.0, 1.0, open_high=True)
    assert fraction.contains(0.0) and fraction.contains(0.999) and not fraction.contains(1.0)
    positive = Param("g", 0.0, open_low=True)
    assert not positive.contains(0.0) and positive.contains(1e-9) and positive.describe() == "> 0"


def test_a_whole_number_where_the_default_is_a_fraction_is_that_fraction(tmp_path):
    """``--param overlap=0`` (YAML reads 0 as a whole number) is the overlap 0.0."""
    from plenocli.pipeline.stages.simulate import simulate

    assert check_params("stereo-rig", generator("stereo-rig"), {"overlap": 0}) == \
        {"overlap": 0.0}
    truth = simulate("stereo-rig", tmp_path / "s", overlap=0, view_shape=[64, 96])
    assert truth["overlap"] == 0.0


@pytest.mark.parametrize("params, words", [
    ({"pitch_px": 1e6}, "leaves fewer than 4 micro-images across"),
    ({"distance_m": 0.01, "scene": "plane"}, "inside the main lens's focal length"),
])
def test_lenslet_depth_refuses_what_it_cannot_render(params, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        generator("lenslet-depth")(**params)


def test_rays_are_bounded_with_the_kinds_default_sensor():
    """audit 8 E13: --rays 100000 on a kind's default 256 px sensor (6.6e9 rays) passed the
    size check, which counted the sensor as 1 x 1 when --pixels was not given."""
    from plenocli.synth import kinds

    generate = kinds()["quadpixel-white"]
    with pytest.raises(ValueError, match="256 x 256 pixels x 100000 rays"):
        check_params("quadpixel-white", generate, {"rays": 100000})
