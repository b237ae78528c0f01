"""Demosaicing: orientation of every pattern, support radius, NaN masks, bands, accuracy."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.colour import demosaic as dm
from plenocli.colour.metrics import colour_error
from plenocli.synth.chart import camera_sampled, colour_chart

PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")


@pytest.mark.parametrize("pattern", PATTERNS)
@pytest.mark.parametrize("method", dm.METHODS)
def test_flat_colour_comes_back_for_every_pattern(pattern, method):
    rgb = np.empty((24, 32, 3), np.float32)
    rgb[...] = (0.8, 0.3, 0.1)
    out = dm.demosaic(dm.mosaic(rgb, pattern), pattern, method=method)
    tol = 0.003 if method == "opencv-vng" else 1e-3  # VNG is 8-bit inside OpenCV
    np.testing.assert_allclose(out[6:-6, 6:-6], rgb[6:-6, 6:-6], atol=tol)


def test_mosaic_keeps_the_filter_colour():
    rgb = np.arange(4 * 4 * 3, dtype=np.float32).reshape(4, 4, 3)
    m = dm.mosaic(rgb, "GRBG")
    assert m[0, 0] == rgb[0, 0, 1] and m[0, 1] == rgb[0, 1, 0]
    assert m[1, 0] == rgb[1, 0, 2] and m[1, 1] == rgb[1, 1, 1]


@pytest.mark.parametrize("method", dm.METHODS)
def test_support_radius_bounds_the_reach_of_one_pixel(method):
    rng = np.random.default_rng(3)
    base = (0.2 + 0.5 * rng.random((48, 48))).astype(np.float32)
    base[0, 0], base[0, 1] = 1.0, 0.0  # fixed range: OpenCV's integer scaling stays the same
    # given gains: the default grey-edge estimate is a mean over the whole frame
    ref = dm.demosaic(base, "RGGB", method=method, gains=(1, 1, 1))
    radius = dm.SUPPORT_RADIUS[method]
    for r, c in ((24, 24), (24, 25), (25, 24), (25, 25)):
        bumped = base.copy()
        bumped[r, c] += 0.2
        out = dm.demosaic(bumped, "RGGB", method=method, gains=(1, 1, 1))
        changed = np.abs(out - ref).max(axis=-1) > 1e-6
        rows, cols = np.nonzero(changed)
        assert changed.any()
        assert np.abs(rows - r).max() <= radius and np.abs(cols - c).max() <= radius


@pytest.mark.parametrize("method", dm.METHODS)
def test_nan_pixels_stay_masked_within_the_radius_only(method):
    rng = np.random.default_rng(4)
    frame = (0.2 + 0.5 * rng.random((40, 40))).astype(np.float32)
    frame[20:22, 18:20] = np.nan  # a clipped highlight
    out = dm.demosaic(frame, "RGGB", method=method)
    radius = dm.SUPPORT_RADIUS[method]
    expected = np.zeros(frame.shape, bool)
    expected[20 - radius:22 + radius, 18 - radius:20 + radius] = True
    np.testing.assert_array_equal(np.isnan(out).any(axis=-1), expected)
    assert np.array_equal(np.isnan(out).all(axis=-1), expected)  # all channels or none


@pytest.mark.parametrize("method", ["menon2007", "rcd"])
def test_bands_give_the_same_result_as_one_pass(monkeypatch, method):
    rng = np.random.default_rng(5)
    frame = rng.random((100, 64)).astype(np.float32)
    whole = dm.demosaic(frame, "GBRG", method=method)
    monkeypatch.setattr(dm, "BAND_ROWS", 22)  # five bands, on several threads for rcd
    np.testing.assert_allclose(dm.demosaic(frame, "GBRG", method=method), whole,
                               rtol=0, atol=1e-6)


def test_default_is_the_most_accurate_on_the_chart():
    truth = camera_sampled(colour_chart(384 * 4, 576 * 4)[0], 4)
    mosaic = dm.mosaic(truth, "RGGB")
    psnr = {m: colour_error(dm.demosaic(mosaic, "RGGB", method=m), truth).psnr_db
            for m in dm.METHODS}
    assert psnr[dm.DEFAULT_METHOD] >= max(psnr.values()) - 0.5
    assert psnr[dm.DEFAULT_METHOD] >= 38.0


@pytest.mark.parametrize("cfa", [None, "RGBW", "RGB", "XYZQ"])
def test_unknown_patterns_are_refused(cfa):
    with pytest.raises(ValueError, match="cfa"):
        dm.demosaic(np.zeros((8, 8), np.float32), cfa)


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="method"):
        dm.demosaic(np.zeros((8, 8), np.float32), "RGGB", method="ahd")


@pytest.mark.parametrize("pattern", PATTERNS)
def test_menon_equals_the_colour_demosaicing_reference(pattern):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour_demosaicing

    frame = np.random.default_rng(8).random((46, 58))
    reference = colour_demosaicing.demosaicing_CFA_Bayer_Menon2007(frame, pattern)
    ours = dm.demosaic(frame.astype(np.float32), pattern, method="menon2007", gains=(1, 1, 1))
    np.testing.assert_allclose(ours, reference, rtol=0, atol=2e-6)


@pytest.mark.parametrize("method", ["rcd", "bilinear"])
def test_out_receives_the_same_pixels_in_place(method):
    """``out`` (a view of a larger, channel-interleaved stack) gets exactly what a fresh array
    gets, NaN reach included; a wrong shape is refused."""
    rng = np.random.default_rng(2)
    frame = rng.random((64, 96)).astype(np.float32)
    frame[20, 30] = np.nan
    fresh = dm.demosaic(frame, "GRBG", method=method, gains=(2.0, 1.0, 1.5))
    stack = np.zeros((2, 64, 96, 3), np.float32)
    got = dm.demosaic(frame, "GRBG", method=method, gains=(2.0, 1.0, 1.5), out=stack[1])
    assert got is stack[1] or np.shares_memory(got, stack)
    assert np.array_equal(stack[1], fresh, equal_nan=True) and not stack[0].any()
    with pytest.raises(ValueError, match="out must be"):
        dm.demosaic(frame, "GRBG", out=np.zeros((64, 96, 3), np.float64))


@pytest.mark.parametrize("method", dm.METHODS)
@pytest.mark.parametrize("site", [(0, 0), (0, 1), (1, 0), (1, 1)])
def test_a_site_with_no_known_pixel_is_refused(method, site):
    # audit 12: an all-NaN red plane was filled with the frame's median (no red left to grow
    # from) and demosaiced as if known
    rng = np.random.default_rng(12)
    frame = (0.2 + 0.5 * rng.random((40, 40))).astype(np.float32)
    frame[site[0]::2, site[1]::2] = np.nan
    with pytest.raises(ValueError, match="cannot be rebuilt from the others"):
        dm.demosaic(frame, "RGGB", method=method)
    frame[site[0], site[1]] = 0.5  # one known pixel of that colour: grown from, not refused
    assert dm.demosaic(frame, "RGGB", method=method).shape == (40, 40, 3)
