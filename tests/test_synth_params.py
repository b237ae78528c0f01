"""The simulated kinds' parameters are declared once (plenocli.synth.params): every parameter a
generator takes has a meaning and a range, and values outside it are refused by name."""

from __future__ import annotations

import inspect
import re

import pytest

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
    ("dualpixel", {"seed": -1}, "seed must be in [0, 4.29497e+09)"),
    ("dualpixel", {"noise": "loud"}, "noise = 'loud' is not a value like its default 2.0"),
    ("dualpixel", {"rays": 2}, "simulate dualpixel does not take 'rays'"),
])
def test_values_out_of_range_are_refused_by_name(kind, params, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        check_params(kind, generator(kind), params)


def test_the_ends_of_a_range():
    fraction = Param("r", 0.0, 1.0, open_high=True)
    assert fraction.contains(0.0) and fraction.contains(0.999) and not fraction.contains(1.0)
    positive = Param("g", 0.0, open_low=True)
    assert not positive.contains(0.0) and positive.contains(1e-9) and positive.describe() == "> 0"
