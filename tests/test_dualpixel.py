import numpy as np

from plenocli.bias import subtract_overscan
from plenocli.dualpixel import split_views
from plenocli.synth.dualpixel import dualpixel_capture


def corrected_views(raw, truth):
    geo, white = truth["geometry"], truth["params"]["white_level"]
    top, left, bottom, right = geo["active_area"]
    frames, clipped = [], []
    for f in range(2):
        out, _ = subtract_overscan(raw[f], active_area=geo["active_area"],
                                   masked_areas=geo["masked_areas"], overscan="left")
        frames.append(out)
        clipped.append(raw[f, top:bottom, left:right] >= white)
    return split_views(frames[0], frames[1], sum_clipped=clipped[0], a_clipped=clipped[1])


def test_noiseless_views_are_exact_and_s_is_a_plus_b():
    raw, truth = dualpixel_capture(seed=2, noise=0.0)
    a, b, s = corrected_views(raw, truth)
    np.testing.assert_array_equal(a, truth["A"])
    np.testing.assert_array_equal(b, truth["B"])
    np.testing.assert_array_equal(s, truth["S"])
    valid = np.isfinite(s) & np.isfinite(a)
    assert valid.mean() > 0.95
    np.testing.assert_array_equal(s[valid], (a + b)[valid])  # exactly, not approximately


def test_clipped_pixels_are_masked_not_wrong():
    raw, truth = dualpixel_capture(seed=2, noise=0.0)
    assert truth["clipped_S"].sum() > 10  # the chart has clipping highlights
    a, b, s = corrected_views(raw, truth)
    assert np.isnan(b[truth["clipped_S"]]).all()
    assert np.isnan(s[truth["clipped_S"]]).all()
    assert np.isfinite(b[~(truth["clipped_S"] | truth["clipped_A"])]).all()


def test_split_varies_across_the_frame_like_the_camera():
    _, truth = dualpixel_capture(seed=0, scene="white", noise=0.0)
    split = truth["split"]
    assert split[:, :10].mean() > 0.55 > 0.45 > split[:, -10:].mean()
