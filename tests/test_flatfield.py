import numpy as np
import pytest

from plenocli.flatfield import apply_gain, white_gain
from plenocli.synth.dualpixel import dualpixel_capture

# The capture flattened by the gain of an independent white (another seed), against the
# simulator's known vignetting and A/S split: corrected / (capture / (vignetting * split)) is
# the gain times the true falloff, one constant per view and CFA colour when the gain is right.
# Measured: max deviation 0.14 % with a noiseless white, mean 0.43-0.59 % with a noisy one
# (photon noise through the 5 x 5 median); the limits are 1.4 x those, so that a regression to
# twice either fails.
FLAT_MAX_NOISELESS = 0.002
FLAT_MEAN_NOISY = 0.008


def _flattened_against_truth(white_noise: float):
    """Per view and CFA plane: |ratio / median - 1| of the corrected capture to its truth."""
    _, white = dualpixel_capture(seed=1, scene="white", noise=white_noise, rows=128, cols=192)
    _, capture = dualpixel_capture(seed=2, scene="chart", rows=128, cols=192)
    for view in ("A", "B"):
        split = capture["split"] if view == "A" else 1 - capture["split"]
        corrected = apply_gain(capture[view], white_gain(white[view], cfa="RGGB", median_px=5))
        ratio = corrected / (capture[view] / (capture["vignetting"] * split))
        for r in range(2):
            for c in range(2):
                plane = ratio[r::2, c::2]
                plane = plane[np.isfinite(plane)]
                assert plane.size > 0.9 * ratio[r::2, c::2].size  # only clipped pixels lost
                yield (view, r, c), np.abs(plane / np.median(plane) - 1)


def test_capture_flattened_by_an_independent_white_loses_the_true_vignetting():
    for key, deviation in _flattened_against_truth(white_noise=0.0):
        assert deviation.max() < FLAT_MAX_NOISELESS, (key, deviation.max())


def test_gain_of_a_noisy_white_is_smoothed_not_copied():
    for key, deviation in _flattened_against_truth(white_noise=2.0):
        assert deviation.mean() < FLAT_MEAN_NOISY, (key, deviation.mean())


def test_gain_inverts_a_known_vignetting():
    yy, xx = np.mgrid[0:64, 0:80]
    vignetting = 1 - 0.4 * (((xx - 40) / 40) ** 2 + ((yy - 32) / 32) ** 2) / 2
    gain = white_gain(1000.0 * vignetting, median_px=1)
    np.testing.assert_allclose(gain, vignetting.max() / vignetting, rtol=1e-6)


def test_floor_masks_dark_pixels_instead_of_amplifying_noise():
    white = np.full((32, 32), 1000.0)
    white[:, :4] = 10.0  # a dark edge: gain 100 would amplify noise
    gain = white_gain(white, median_px=1, floor=0.05)
    assert np.isnan(gain[:, :4]).all()
    np.testing.assert_allclose(gain[:, 4:], 1.0)


@pytest.mark.parametrize("shape", [(1, 1), (1, 50), (50, 1), (2, 1)])
def test_a_bayer_image_narrower_than_its_cell_is_named_not_given_a_window(shape):
    """audit 12: a 1-px-wide Bayer view was told "the median window of 1 px is larger than the
    image (0 pixels of one colour across); use at most 1"."""
    with pytest.raises(ValueError, match="narrower than one 2 x 2 cell of its RGGB") as err:
        white_gain(np.full(shape, 1000.0), cfa="RGGB", median_px=1)
    assert "at most" not in str(err.value)


def test_percentile_reference_ignores_a_hot_cluster():
    white = np.full((64, 64), 1000.0)
    white[10:20, 10:20] = 5000.0  # larger than the median window: survives filtering
    by_max = white_gain(white, median_px=3, reference="max")
    by_pct = white_gain(white, median_px=3, reference="percentile", percentile=90)
    assert np.nanmedian(by_max) == pytest.approx(5.0)
    assert np.nanmedian(by_pct) == pytest.approx(1.0)


def test_nan_in_white_is_ignored():
    white = np.full((16, 16), 500.0)
    white[3, 3] = np.nan
    gain = white_gain(white, median_px=3)
    assert np.isnan(gain[3, 3]) and np.isfinite(np.delete(gain.ravel(), 3 * 16 + 3)).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"reference": "mean"}, "reference must be"),
    ({"median_px": 4}, "median_px must be a positive odd"),
    ({"floor": 1.5}, "floor must be"),
])
def test_bad_options_name_the_parameter(kwargs, message):
    with pytest.raises(ValueError, match=message):
        white_gain(np.ones((8, 8)), **kwargs)
