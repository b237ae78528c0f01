"""Dual-pixel highlight recovery: S rebuilt from A and the white image's A/S split."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli import dualpixel
from plenocli.synth.dualpixel import dualpixel_capture

WHITE_LEVEL = 15000.0


def test_overexposed_scene_is_rebuilt_within_one_percent():
    _, white = dualpixel_capture(seed=11, rows=128, cols=192, scene="white", signal=6000.0,
                                 noise=2.0)
    true_split = white["split"].astype(np.float64)  # the simulator's A/S
    rows, cols = true_split.shape
    # a known scene overexposed by up to one stop: S from 0.3 to 2 x the clipping level
    rr, cc = np.mgrid[0:rows, 0:cols]
    s_true = WHITE_LEVEL * (0.3 + 1.7 * (cc / (cols - 1)) * (0.6 + 0.4 * rr / (rows - 1)))
    s_true[10:30, 4:24] = 2.0 * WHITE_LEVEL  # on the left, where A takes the larger share
    a_true = true_split * s_true
    s_seen = np.where(s_true >= WHITE_LEVEL, np.nan, s_true).astype(np.float32)
    a_seen = np.where(a_true >= WHITE_LEVEL, np.nan, a_true).astype(np.float32)

    split = dualpixel.highlight_split(white["A"], white["S"], cfa="RGGB")
    views, rebuilt = dualpixel.recover_highlights(a_seen, s_seen, split)

    clipped_s_only = (s_true >= WHITE_LEVEL) & (a_true < WHITE_LEVEL)
    assert clipped_s_only.sum() > 1000 and ((a_true >= WHITE_LEVEL).sum() > 100)
    np.testing.assert_array_equal(rebuilt, clipped_s_only)
    a_fine = a_true < WHITE_LEVEL
    np.testing.assert_allclose(views[2][a_fine], s_true[a_fine], rtol=0.01)
    np.testing.assert_allclose(views[1][a_fine], (s_true - a_true)[a_fine],
                               rtol=0.01 * 1 / 0.4)  # B is S - A: S's error over B's share
    assert np.isnan(views[2][~a_fine]).all() and np.isnan(views[1][~a_fine]).all()
    np.testing.assert_array_equal(views[0], a_seen)
    unclipped = s_true < WHITE_LEVEL
    np.testing.assert_array_equal(views[2][unclipped], s_seen[unclipped])  # untouched


def test_split_follows_the_white_image():
    _, white = dualpixel_capture(seed=2, rows=96, cols=128, scene="white", noise=2.0)
    split = dualpixel.highlight_split(white["A"], white["S"], cfa="RGGB")
    np.testing.assert_allclose(split, white["split"], rtol=0.01)


def test_shapes_and_sizes_are_checked():
    with pytest.raises(ValueError, match="shape"):
        dualpixel.recover_highlights(np.zeros((4, 4)), np.zeros((4, 5)), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="degree"):
        dualpixel.highlight_split(np.ones((8, 8)), np.ones((8, 8)), cfa=None, degree=-1)
    with pytest.raises(ValueError, match="split"):  # A = S: not a dual-pixel pair
        dualpixel.highlight_split(np.ones((16, 16)), np.ones((16, 16)), cfa="RGGB")
