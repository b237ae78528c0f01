"""plenocli.synth.mixing: the known mixing field, masked whites, and the ghost capture sets."""

from __future__ import annotations

import json

import numpy as np
import pytest

from plenocli.pipeline.stages.simulate import simulate
from plenocli.synth import mixing as sim_mixing
from plenocli.synth import prismcam


@pytest.mark.parametrize("n_views,r", [(2, 0.5), (4, 0.13)])
def test_field_has_unit_diagonal_and_mean_r(n_views, r):
    field = sim_mixing.mixing_field((60, 90), n_views=n_views, r=r, colours=("R", "G", "B"),
                                    seed=1)
    for k in range(n_views):
        np.testing.assert_array_equal(field[:, k, k], 1.0)
    # the slopes and the curvature average out over the frame: mean M_kj = r * colour scale
    for c, scale in enumerate((1.1, 1.0, 0.85)):
        for k in range(n_views):
            for j in range(n_views):
                if k != j:
                    diagonal = n_views == 4 and (k ^ j) == 3
                    expected = r * scale * (0.4 if diagonal else 1.0)
                    assert field[c, k, j].mean() == pytest.approx(expected, rel=1e-3)
    with pytest.raises(ValueError, match="n_views"):
        sim_mixing.mixing_field((8, 8), n_views=3, r=0.1)


def test_masked_whites_and_mixing_are_consistent():
    rng = np.random.default_rng(0)
    field = sim_mixing.mixing_field((20, 30), n_views=2, r=0.3, colours=("R", "G", "B"))
    colours = sim_mixing.colour_index((20, 30), "RGGB")
    whites = rng.uniform(0.5, 1.0, (2, 20, 30))
    # all parts open = the sum of the masked whites = the mixed whites
    total = sum(sim_mixing.masked_white(whites, field, j, colours) for j in range(2))
    np.testing.assert_allclose(total, sim_mixing.apply_mixing(whites, field, colours))
    assert colours[0, 0] == 0 and colours[0, 1] == 1 and colours[1, 1] == 2


def test_raytrix_ghost_shares_the_prismcam_lattice_and_light():
    sim = sim_mixing.render_raytrix_ghost(pixels=240, seed=3)
    white, _ = prismcam.render_raytrix(pixels=240, seed=3, scene="white", prism=False)
    np.testing.assert_allclose(sim["white"], white, atol=1e-6)
    np.testing.assert_allclose(sim["masked_left"] + sim["masked_right"], sim["white"],
                               atol=1e-12)
    differs = np.abs(sim["ghosted"] - sim["clean"]) > 1e-3
    assert 0.02 < differs.mean() < 0.5  # only pixels near a micro-lens centre mix


def test_ghost_kinds_write_their_files(tmp_path):
    truth = simulate("quadpixel-ghost-mask", tmp_path / "q", pixels=64)
    assert truth["r"] == 0.03 and truth["light"] == 0.84
    for name in truth["files"].values():
        assert (tmp_path / "q" / name).stat().st_size > 0
    saved = json.loads((tmp_path / "q" / "truth.json").read_text())
    assert saved["views"] == ["S00", "S01", "S10", "S11"]
    assert saved["mixing_r_max_per_colour"]["R"] > saved["mixing_r_max_per_colour"]["B"]
