"""The calibration's compiled helpers against plain formulas: they only make the search faster,
so each must give exactly what the formula it replaced gives."""

import numpy as np
import pytest

from plenocli.calibration.candidates import Lattice, distinct
from plenocli.calibration.lenstypes import _disc_means
from plenocli.calibration.verify import Autocorrelation, _annulus_lags
from plenocli.model.lensgrid import LensGrid


def _first_of_each(lattices):
    kept = []
    for lat in lattices:
        if not any(lat.same_as(other) for other in kept):
            kept.append(lat)
    return kept


@pytest.mark.parametrize("seed", range(5))
def test_distinct_keeps_the_first_of_each_same_lattice(seed):
    rng = np.random.default_rng(seed)
    # near-duplicates in pitch and angle, across the angle period and both kinds
    lattices = [Lattice(str(rng.choice(["hex", "square"])),
                        float(20 * np.exp(rng.normal(0, 0.015))),
                        float(rng.normal(0, 0.015) + rng.choice([0.0, np.pi / 3, np.pi / 2])))
                for _ in range(300)]
    kept = distinct(lattices)
    assert kept == _first_of_each(lattices)
    assert 1 < len(kept) < len(lattices)
    assert distinct([]) == []


def test_annulus_lags_are_the_lattice_vectors_in_the_annulus():
    basis = np.array([[7.3, 1.2], [2.6, 6.9]])
    lo, hi, n = 15.0, 60.0, 12
    pts, k, m = _annulus_lags(basis, lo, hi, n)
    kk, mm = np.meshgrid(np.arange(-n, n + 1), np.arange(0, n + 1), indexing="ij")
    kk, mm = kk.ravel(), mm.ravel()
    xy = kk[:, None] * basis[0] + mm[:, None] * basis[1]
    inside = (np.hypot(*xy.T) >= lo) & (np.hypot(*xy.T) <= hi)
    np.testing.assert_array_equal(pts, xy[inside])
    np.testing.assert_array_equal(k, kk[inside])
    np.testing.assert_array_equal(m, mm[inside])


def test_autocorrelation_sample_is_bilinear_and_clamped():
    a = np.random.default_rng(1).normal(size=(41, 37)).astype(np.float32)
    lags = np.array([[0.0, 0.0], [3.25, -7.5], [-18.0, 20.0], [17.9, -19.99], [40.0, 0.3],
                     [-2.7, 1.1]])
    got = Autocorrelation._sample(lags, a)
    for (dx, dy), value in zip(lags, got, strict=True):
        x = min(max(dx + 37 // 2, 0.0), 36.0)
        y = min(max(dy + 41 // 2, 0.0), 40.0)
        x0, y0 = min(int(x), 35), min(int(y), 39)
        fx, fy = x - x0, y - y0
        want = ((1 - fy) * ((1 - fx) * a[y0, x0] + fx * a[y0, x0 + 1])
                + fy * ((1 - fx) * a[y0 + 1, x0] + fx * a[y0 + 1, x0 + 1]))
        assert value == pytest.approx(float(want), rel=1e-12, abs=1e-12)


def test_disc_means_mirror_at_the_border_only():
    image = np.random.default_rng(2).normal(size=(30, 40)).astype(np.float32)
    yy, xx = np.mgrid[-3:4, -3:4]
    inside = np.hypot(xx, yy) <= 3.2
    dy, dx = yy[inside].astype(np.int64), xx[inside].astype(np.int64)
    r = np.array([0, 15, 29, 2, 27, 15])
    c = np.array([0, 20, 39, 38, 1, 3])
    padded = np.pad(image, 4, mode="symmetric")   # edge pixel repeated, as BORDER_REFLECT
    want = [padded[r[k] + 4 + dy, c[k] + 4 + dx].astype(np.float64).mean() for k in range(6)]
    np.testing.assert_allclose(_disc_means(image, r, c, dy, dx), want, rtol=1e-6)


def test_grid_refuses_a_lens_listed_twice_however_its_indices_are_stored():
    grid = LensGrid(20.0, 0.1, (100.0, 100.0), "hex", image_shape=(200, 200))
    idx, centres = grid.lens_centres()
    LensGrid(20.0, 0.1, (100.0, 100.0), centres_xy=centres, indices=idx)
    for twice in (np.vstack([idx, idx[3:4]]), np.vstack([idx, idx[3:4]]).astype(float)):
        with pytest.raises(ValueError, match="listed twice"):
            LensGrid(20.0, 0.1, (100.0, 100.0), centres_xy=np.vstack([centres, centres[3:4]]),
                     indices=twice)
    with pytest.raises(ValueError, match="compact block"):
        LensGrid(20.0, 0.1, (100.0, 100.0), centres_xy=np.zeros((2, 2)),
                 indices=np.array([[0, 0], [10 ** 5, 3]]))


def test_a_lattice_is_described_by_its_smallest_turn():
    """audit 11 E4: a refused hex lattice was shown "at 60.00 deg" beside a grid at 0 deg, the
    same lattice; its angle is shown as its smallest turn from the x axis."""
    assert Lattice("hex", 20.2, np.radians(59.99)).describe() == "hex 20.20 px at -0.01 deg"
    assert Lattice("hex", 20.2, np.radians(29.0)).describe() == "hex 20.20 px at 29.00 deg"
    assert Lattice("square", 20.2, np.radians(89.0)).describe() == "square 20.20 px at -1.00 deg"
