"""plenocli.crosstalk: known ratios, maps, colours, NaN, the mask-width sweep, real data."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from plenocli.crosstalk import crosstalk_ratio, mask_width_sweep
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
    with pytest.raises(ValueError, match="at least 2 views"):
        crosstalk_ratio(np.ones((1, 10, 10)))
    with pytest.raises(ValueError, match="no pixel is finite"):
        crosstalk_ratio(np.full((2, 10, 10), np.nan))
    with pytest.raises(ValueError, match="tile_px"):
        crosstalk_ratio(np.ones((2, 10, 10)), tile_px=3)
    with pytest.raises(ValueError, match="received no light"):
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


# --- the whole mixing matrix M (measure_mixing) ---------------------------------------------

RGGB = np.array([[0, 1], [1, 2]])


@pytest.mark.parametrize("noise", [0.0, 0.003])
def test_measured_mixing_matches_the_simulator_per_tile(noise):
    from plenocli.crosstalk import measure_mixing
    from plenocli.synth import mixing as sim_mixing

    sim = sim_mixing.render_dualpixel_ghost(pixels=384, r=0.5, seed=3)
    rng = np.random.default_rng(5)
    masked = [sim["masked"][n] + rng.normal(0.0, noise, sim["masked"][n].shape) for n in "AB"]
    field = measure_mixing(masked, intended=[0, 1], views=["A", "B"], tile_px=32,
                           colour_pattern=RGGB, colours=("R", "G", "B"))
    whites = np.stack([sim["masked"]["A"][0], sim["masked"]["B"][1]])
    truth = sim_mixing.tile_truth(sim["field"], whites, 32,
                                  sim_mixing.colour_index(whites.shape[1:], "RGGB"))
    assert np.abs(field.nodes - truth).max() < 0.005
    assert field.nodes.shape == (3, 2, 2, 8, 12)
    np.testing.assert_array_equal(field.nodes[:, [0, 1], [0, 1]], 1.0)
    np.testing.assert_allclose(field.node_rows[:2], [15.5, 47.5])


def test_r_is_consistent_with_mixing():
    from plenocli.crosstalk import measure_mixing, mixing_ratio
    from plenocli.synth import mixing as sim_mixing

    rows, cols = 64, 96
    field = sim_mixing.mixing_field((rows, cols), n_views=4, r=0.13, seed=1)
    whites = np.ones((4, rows, cols))
    masked = [sim_mixing.masked_white(whites, field, j) for j in range(4)]
    measured = measure_mixing(masked, intended=[0, 1, 2, 3], views=["a", "b", "c", "d"],
                              tile_px=16)
    ratios = mixing_ratio(measured)
    # uniform white: the paper's r of capture j is the mean of M_kj over the frame
    for j in range(4):
        r = crosstalk_ratio(masked[j], intended=j)["r"]
        mean_mkj = max(field[0, k, j].mean() for k in range(4) if k != j)
        assert r == pytest.approx(mean_mkj, abs=1e-6)
        assert r == pytest.approx(max(measured.nodes[0, k, j].mean() for k in range(4)
                                      if k != j), abs=2e-3)
    off = ~np.eye(4, dtype=bool)
    assert ratios["r_max"] == pytest.approx(float(measured.nodes[0][off].max()))
    assert 0.12 < ratios["r_mean"] < 0.14


def test_measure_mixing_refuses_bad_sets():
    from plenocli.crosstalk import measure_mixing

    white = np.ones((2, 8, 8))
    with pytest.raises(ValueError, match="one masked white per pupil part"):
        measure_mixing([white], intended=[0], views=["A", "B"])
    with pytest.raises(ValueError, match="one masked white per pupil part"):
        measure_mixing([white, white], intended=[0, 0], views=["A", "B"])
    with pytest.raises(ValueError, match="no tile"):
        dark = np.zeros((2, 8, 8))
        measure_mixing([white, dark], intended=[0, 1], views=["A", "B"], tile_px=4)
    # globally the open part is brighter, but in one tile the other view is: r >= 100 % there
    a_open = np.stack([np.ones((8, 8)), np.full((8, 8), 0.3)])
    a_open[1, :4, 4:] = 1.2
    with pytest.raises(ValueError, match=r"records 120 % .* tile \(0, 1\)"):
        measure_mixing([a_open, a_open[::-1]], intended=[0, 1], views=["A", "B"], tile_px=4)


def test_a_tile_larger_than_the_image_is_refused_before_allocating():
    views = np.ones((2, 40, 60), np.float32)
    with pytest.raises(ValueError, match="larger than the 60 x 40 image"):
        crosstalk_ratio(views, tile_px=100_000)


def test_a_white_of_scattered_known_pixels_is_refused_not_measured():
    """audit 12 W7: a white 99 % unknown gave r from 6 pixels and a map of no tile (exit 0);
    r needs a tile known well enough to map it, in every colour; the mixing says the pixels
    are unknown (not "no tile has light")."""
    from plenocli.crosstalk import measure_mixing

    views, _ = make_masked_white(r=0.13, cfa="RGGB", n_views=2, intended=0, seed=5)
    sparse = views.copy()
    sparse[:, np.random.default_rng(1).random(views.shape[1:]) < 0.99] = np.nan
    with pytest.raises(ValueError, match=r"too few pixels are known in every view"):
        crosstalk_ratio(sparse, cfa="RGGB", tile_px=16)
    no_red = views.copy()
    no_red[:, ::2, ::2] = np.nan
    with pytest.raises(ValueError, match=r"too few pixels of colour R are known"):
        crosstalk_ratio(no_red, cfa="RGGB", tile_px=16)
    with pytest.raises(ValueError, match=r"no 16 px tile has 25 % of its colour L pixels known"):
        measure_mixing([sparse, sparse[::-1]], intended=[0, 1], views=["A", "B"], tile_px=16)
