"""Sellmeier indices against the Schott catalogue's n_d."""

import numpy as np
import pytest

from plenocli.optics.glass import CATALOGUE_ND, D_LINE_UM, SELLMEIER, refractive_index


@pytest.mark.parametrize("glass", ["N-SK16", "SK16", "F5", "N-BK7", "N-SF11", "air"])
def test_nd_matches_catalogue(glass):
    assert abs(refractive_index(glass, D_LINE_UM) - CATALOGUE_ND[glass.upper()]) < 1e-5


def test_normal_dispersion_and_vectorised():
    lam = np.array([0.4861, 0.5876, 0.6563])  # F, d, C lines
    for glass in SELLMEIER:
        n = refractive_index(glass, lam)
        assert n.shape == (3,) and np.all(np.diff(n) < 0)  # index falls with wavelength


def test_abbe_number_of_n_bk7():
    n_f, n_d, n_c = refractive_index("N-BK7", np.array([0.4861327, 0.5875618, 0.6562725]))
    assert abs((n_d - 1) / (n_f - n_c) - 64.17) < 0.05  # Schott: nu_d = 64.17


def test_constant_index_and_case():
    assert refractive_index(1.74) == 1.74
    assert refractive_index("n-bk7") == refractive_index("N-BK7")


@pytest.mark.parametrize("glass, wavelength, match", [
    ("unobtainium", 0.5876, "unknown glass"), ("N-BK7", 587.6, "micrometres"),
    (0.5, 0.5876, "below 1")])
def test_bad_input(glass, wavelength, match):
    with pytest.raises(ValueError, match=match):
        refractive_index(glass, wavelength)
