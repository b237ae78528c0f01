"""plenocli.crosstalk: known ratios, maps, colours, NaN, the mask-width sweep, real data."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from plenocli.crosstalk import crosstalk_ratio, mask_width_sweep
from plenocli.errors import InputError
from plenocli.synth.rig import make_masked_white


@pytest.mark.parametrize("n_views,intended,r", [(2, 0, 0.5), (2, 1, 0.03), (4, 2, 0.13)])
def test_known_ratio_within_1_point(n_views, intended, r):
    views, truth = make_masked_white(n_views=n_views, intended=intended, r=r, noise=3.0, seed=1)
    res = crosstalk_ratio(views)
    assert res["intended"] == intended
    assert abs(res["r"] - truth["r"]) < 0.01
    assert truth["r"] == pytest.approx(r, abs=1e-9)


def test_map_follows_position():
    views, _ = make_masked_white(r=0.13, r_slope=0.06, view_shape=(64, 128), seed=2)
    res = crosstalk_ratio(views, tile_px=32)
    cols = 128
    centres = (np.arange(4) * 32 + 15.5) / (cols - 1) - 0.5
    np.testing.assert_allclose(res["map"], np.broadcast_to(0.13 + 0.06 * centres, (2, 4)),
                               atol=2e-3)


def test_per_colour_and_nan_ignored():
    views, truth = make_masked_white(r=0.13, cfa="RGGB", n_views=4, intended=0,
                                     r_per_colour={"R": 0.16, "G": 0.13, "B": 0.09}, seed=3)
    views[1, :20, :30] = np.nan
    views[2, 40:, 50:] = 1e9 * np.nan
    res = crosstalk_ratio(views, cfa="RGGB", tile_px=16)
    for colour in "RGB":
        assert res["per_colour"][colour]["r"] == pytest.approx(truth["r_per_colour"][colour],
                                                               abs=1e-3)
    assert res["valid_fraction"] < 1
    assert np.isfinite(res["r"])


def test_bad_inputs():
    with pytest.raises(InputError, match="at least 2 views"):
        crosstalk_ratio(np.ones((1, 10, 10)))
    with pytest.raises(InputError, match="no pixel is finite"):
        crosstalk_ratio(np.full((2, 10, 10), np.nan))
    with pytest.raises(ValueError, match="tile_px"):
        crosstalk_ratio(np.ones((2, 10, 10)), tile_px=3)
    with pytest.raises(InputError, match="received no light"):
        crosstalk_ratio(np.zeros((2, 10, 10)), intended=0)


def test_mask_width_sweep_with_synthetic_producer():
    base, _ = make_masked_white(view_shape=(40, 60), r=1.0, vignetting=0.2)

    def make_views(m: float):  # cross-talk falls as the mask widens: r = 0.3 exp(-m)
        return base[0], base[0] * 0.3 * np.exp(-m)

    sweep = mask_width_sweep(make_views, [0, 1, 2, 3], intended="left", tile_px=20)
    r = [row["r"] for row in sweep]
    np.testing.assert_allclose(r, 0.3 * np.exp(-np.arange(4.0)), rtol=1e-6)
    assert all(a > b for a, b in zip(r, r[1:], strict=False))
    with pytest.raises(ValueError, match="intended"):
        mask_width_sweep(make_views, [0], intended="up")


@pytest.mark.realdata
def test_pixel4_white_sheet_map_is_sane(realdata):
    folder = realdata / "dualpixel" / "pixel4"
    pair = []
    for side in ("left", "right"):
        img = cv2.imread(str(folder / f"white_sheet_{side}.png"), cv2.IMREAD_UNCHANGED)
        if img is None:
            pytest.skip(f"white_sheet_{side}.png not found")
        pair.append(img.astype(np.float64) - 1024.0)
    res = crosstalk_ratio(np.stack(pair), tile_px=64)
    finite = res["map"][np.isfinite(res["map"])]
    assert finite.size == res["map"].size
    assert 0.0 <= finite.min() and finite.max() <= 1.0
    assert 0.0 <= res["r"] <= 1.0
