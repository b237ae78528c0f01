"""plenocli.model.cfa: the one Bayer-pattern check, used by decode, refocus and crosstalk."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.crosstalk import crosstalk_ratio
from plenocli.model.cfa import BAYER_PATTERNS, check_pattern, is_bayer, shift_pattern


@pytest.mark.parametrize("cfa", BAYER_PATTERNS)
def test_the_four_bayer_patterns_pass_in_any_case(cfa):
    assert check_pattern(cfa.lower()) == cfa and is_bayer(cfa.lower())


@pytest.mark.parametrize("cfa", ["RGBB", "RRGB", "GGRB", "RGGX", "RGG", "RGGBG", "", None, 4])
def test_anything_else_is_refused(cfa):
    with pytest.raises(ValueError, match="not a 2 x 2 Bayer pattern"):
        check_pattern(cfa)
    assert not is_bayer(cfa)


def test_every_shift_of_a_bayer_pattern_is_bayer():
    for cfa in BAYER_PATTERNS:
        for row in range(2):
            for col in range(2):
                assert is_bayer(shift_pattern(cfa, row, col))


def test_crosstalk_refuses_a_pattern_without_two_greens():
    views = np.ones((2, 8, 8))
    views[1] *= 0.1
    with pytest.raises(ValueError, match="'RGBB' is not a 2 x 2 Bayer pattern"):
        crosstalk_ratio(views, cfa="RGBB", tile_px=4)
