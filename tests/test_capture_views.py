"""dualpixel.capture_views: a decoded capture's frames -> bias-corrected views of the active
area (the library half of the bias stage)."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.dualpixel import capture_views
from plenocli.synth.dualpixel import dualpixel_capture


def _views(raw, truth, names=("S", "A"), **options):
    geometry, white = truth["geometry"], truth["params"]["white_level"]
    return capture_views(raw, names=list(names), active_area=geometry["active_area"],
                         masked_areas=geometry["masked_areas"], black_level=[None, None],
                         white_level=[float(white)] * 2, cfa=geometry["cfa"],
                         **{"overscan": "left", **options})


def test_noiseless_dual_pixel_capture_gives_the_true_views():
    raw, truth = dualpixel_capture(seed=2, noise=0.0)
    result = _views(raw, truth)
    assert result.names == ("A", "B", "S")
    for k, name in enumerate(result.names):
        np.testing.assert_array_equal(result.views[k], truth[name])
    assert [info["mode"] for info in result.levels] == ["left", "left"]
    assert result.white_level == (truth["params"]["white_level"],) * 3


def test_other_frames_stay_as_they_are():
    raw, truth = dualpixel_capture(seed=3, noise=0.0)
    result = _views(raw, truth, names=("one", "two"))
    assert result.names == ("one", "two")
    np.testing.assert_array_equal(result.views[0], truth["S"])
    np.testing.assert_array_equal(result.views[1], truth["A"])


def test_a_bad_frame_is_named():
    raw, truth = dualpixel_capture(seed=4, noise=0.0)
    with pytest.raises(ValueError, match="frame S: .*overscan"):
        _views(raw, truth, overscan="sideways")
