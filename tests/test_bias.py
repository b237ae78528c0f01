import numpy as np
import pytest

from plenocli.bias import column_levels, row_levels, subtract_overscan
from plenocli.synth.dualpixel import dualpixel_capture


def frame_with_bias(rows=40, cols=60, top=6, left=10, seed=0):
    """A frame whose bias varies per row and column phase; the signal is a ramp."""
    rng = np.random.default_rng(seed)
    row_bias = 500 + rng.integers(-20, 20, (rows, 2)).astype(float)
    frame = row_bias[:, np.arange(cols) % 2].copy()
    frame[top:, left:] += np.arange(cols - left)[None, :] * 3.0
    return frame, row_bias


def test_row_levels_recover_per_row_per_phase_bias():
    frame, truth = frame_with_bias()
    np.testing.assert_array_equal(row_levels(frame, (0, 10)), truth)


def test_row_levels_absolute_phase_with_odd_start():
    frame, truth = frame_with_bias()
    np.testing.assert_array_equal(row_levels(frame, (1, 9)), truth)


def test_a_row_whose_few_overscan_samples_disagree_keeps_their_median():
    """audit 20 W2: with two over-scan samples of a colour per row (503, 519; here 500, 522)
    both lay beyond the outlier cut, and the row's level was 0: its whole black (~512 DN)
    left in, exit 0."""
    rng = np.random.default_rng(3)
    frame = 512 + rng.normal(0, 2, (40, 4))
    frame[12, 1], frame[12, 3] = 500.0, 522.0
    levels = row_levels(frame, (0, 4))
    assert levels[12, 1] == pytest.approx(511.0)
    assert np.all(np.abs(levels - 512) < 10)


def test_column_levels_is_row_levels_transposed():
    frame, _ = frame_with_bias()
    np.testing.assert_array_equal(column_levels(frame.T, (0, 10)), row_levels(frame, (0, 10)).T)


@pytest.mark.parametrize("mode", ["left", "both", "auto"])
def test_subtract_overscan_exact_on_noiseless_frame(mode):
    frame, _ = frame_with_bias()
    out, info = subtract_overscan(frame, active_area=[6, 10, 40, 60],
                                  masked_areas=[[0, 0, 40, 10], [0, 10, 6, 60]], overscan=mode,
                                  guard=1)
    expected = np.arange(50)[None, :] * 3.0
    np.testing.assert_allclose(out, np.broadcast_to(expected, (34, 50)), atol=1e-4)
    assert info["mode"] == ("left" if mode == "auto" else mode)


def test_top_overscan_recovers_per_column_bias():
    rng = np.random.default_rng(3)
    col_bias = 300 + rng.integers(-9, 9, (2, 50)).astype(float)  # per row phase, per column
    frame = np.empty((40, 50))
    for p in range(2):
        frame[p::2] = col_bias[p]
    frame[8:] += 100.0
    out, info = subtract_overscan(frame, active_area=[8, 0, 40, 50],
                                  masked_areas=[[0, 0, 8, 50]], overscan="top", guard=0)
    np.testing.assert_allclose(out, 100.0, atol=1e-4)


def test_none_uses_black_level_per_position():
    frame = np.tile(np.array([[10.0, 20.0], [30.0, 40.0]]), (4, 4))
    out, _ = subtract_overscan(frame, active_area=[0, 0, 8, 8], masked_areas=[], overscan="auto",
                               black_level=[10, 20, 30, 40])
    np.testing.assert_array_equal(out, 0.0)


@pytest.mark.parametrize("seed", [0, 5, 11])
def test_noisy_fixture_row_bias_within_half_dn(seed):
    # Canon's geometry: 136 over-scan columns; 2 DN read noise plus photon noise in the image
    raw, truth = dualpixel_capture(seed=seed, rows=192, cols=256, top=16, left=136, noise=2.0)
    for f in range(2):
        _, info = subtract_overscan(raw[f], active_area=truth["geometry"]["active_area"],
                                    masked_areas=truth["geometry"]["masked_areas"],
                                    overscan="left", smooth=9)
        error = info["row_levels"] - truth["row_bias"][f, 16:]
        assert np.abs(error).max() < 0.5, np.abs(error).max()
        assert np.abs(error).mean() < 0.2


def test_does_not_modify_input():
    frame, _ = frame_with_bias()
    before = frame.copy()
    subtract_overscan(frame, active_area=[6, 10, 40, 60], masked_areas=[[0, 0, 40, 10]])
    np.testing.assert_array_equal(frame, before)


def test_bad_mode_and_missing_area_name_the_problem():
    frame, _ = frame_with_bias()
    with pytest.raises(ValueError, match="overscan must be one of"):
        subtract_overscan(frame, active_area=[6, 10, 40, 60], masked_areas=[], overscan="right")
    with pytest.raises(ValueError, match="no usable over-scan columns"):
        subtract_overscan(frame, active_area=[6, 10, 40, 60], masked_areas=[], overscan="left")


AREAS = dict(active_area=[6, 10, 40, 60], masked_areas=[[6, 0, 40, 10], [0, 10, 6, 60]])


@pytest.mark.parametrize("options,words", [
    (dict(guard=99999), "guard 99999 leaves 0 of the 10 columns of the left over-scan"),
    # audit 20 M1: 'leaves no over-scan pixel' where 2 were left, and 'use --guard 0 or less'
    (dict(guard=4, overscan="left"), "leaves 2 of the 10 columns of the left over-scan, fewer "
                                     "than the 4"),
    (dict(guard=4, overscan="left"), "a level needs; use --guard 3 or less"),
    (dict(guard=2, overscan="top"), "leaves 2 of the 6 rows of the top over-scan, fewer than "
                                    "the 4 .* use --guard 1 or less"),
    (dict(smooth=100000), "smooth 100000 is longer than the 17 rows"),
    (dict(smooth=-1), "smooth must be a whole number"),
    (dict(guard=1.5), "guard must be a whole number"),
    (dict(active_area=[6, 10, 41, 60]), "not inside the 60 x 40 frame"),
    (dict(active_area=[6, 10, 6, 60]), "not inside"),
])
def test_options_that_do_not_fit_the_frame_are_refused(options, words):
    frame, _ = frame_with_bias()
    with pytest.raises(ValueError, match=words):
        subtract_overscan(frame, **{**AREAS, **options})


def test_top_overscan_missing_is_named():
    frame, _ = frame_with_bias()
    with pytest.raises(ValueError, match="no usable over-scan rows above"):
        subtract_overscan(frame, active_area=AREAS["active_area"],
                          masked_areas=AREAS["masked_areas"][:1], overscan="top")


def test_an_overscan_that_leaves_active_rows_out_is_not_used_for_them():
    """audit 24 W1: a left over-scan of rows 16-29 only gave the rows past it the last
    measured row's level (14 DN off on the simulator's capture, exit 0). It measures its own
    rows' bias only: --overscan left is refused, auto takes the top over-scan, else none."""
    frame, _ = frame_with_bias()
    partial = [[16, 0, 30, 10], [0, 10, 6, 60]]
    for mode in ("left", "both"):
        with pytest.raises(ValueError, match="the left over-scan covers rows 16-29 only, but "
                                             "the active area's are 6-39"):
            subtract_overscan(frame, active_area=[6, 10, 40, 60], masked_areas=partial,
                              overscan=mode, guard=1)
    _, info = subtract_overscan(frame, active_area=[6, 10, 40, 60], masked_areas=partial,
                                guard=1)
    assert info["mode"] == "top"
    _, info = subtract_overscan(frame, active_area=[6, 10, 40, 60],
                                masked_areas=partial[:1], black_level=[500] * 4)
    assert info["mode"] == "none"
    with pytest.raises(ValueError, match="the top over-scan covers columns 10-39 only"):
        subtract_overscan(frame, active_area=[6, 10, 40, 60],
                          masked_areas=[[0, 10, 6, 40]], overscan="top", guard=1)
