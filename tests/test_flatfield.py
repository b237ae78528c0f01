import numpy as np
import pytest

from plenocli.flatfield import apply_gain, white_gain
from plenocli.synth.dualpixel import dualpixel_capture


def test_white_corrected_by_its_own_gain_is_flat():
    _, truth = dualpixel_capture(seed=1, scene="white", noise=0.0, rows=128, cols=192)
    for view in ("A", "B"):
        white = truth[view]
        corrected = apply_gain(white, white_gain(white, cfa="RGGB", median_px=5))
        for r in range(2):
            for c in range(2):
                plane = corrected[r::2, c::2]
                plane = plane[np.isfinite(plane)]
                spread = (plane.max() - plane.min()) / plane.max()
                assert spread < 0.005, (view, r, c, spread)


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
