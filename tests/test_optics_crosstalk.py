"""Sub-aperture cross-talk of a quad-pixel sensor behind a traced lens."""

import math

import numpy as np
import pytest

from plenocli.io.lensfile import read_lens
from plenocli.optics.analysis import image_distance
from plenocli.optics.crosstalk import (
    crosstalk_ratio,
    crosstalk_report,
    intended_sai,
    sai_flux,
    stop_mask,
)
from plenocli.optics.lens import Lens, Surface
from tests.conftest import ROOT

FAST = dict(fields_across=5, pupil_rays_across=40)


def test_ratio_definition():
    flux = np.array([[100.0, 13.0], [5.0, 2.0]])
    assert crosstalk_ratio(flux, (0, 0)) == pytest.approx(0.13)
    assert crosstalk_ratio(flux, (1, 1)) == pytest.approx(50.0)


@pytest.mark.parametrize("quarter", ["++", "+-", "-+", "--"])
def test_a_nearly_ideal_lens_has_no_crosstalk(quarter):
    # Slow, long lens, tiny field: the exit pupil is imaged cleanly onto the pixels.
    lens = Lens((Surface(math.inf, 0.0, "air", 2.0, stop=True),
                 Surface(400.0, 1.0, "N-BK7", 4.0), Surface(-400.0, 0.0, "air", 4.0)))
    lens = lens.with_image_distance(image_distance(lens))
    res = sai_flux(lens, sensor_mm=0.05, quarter=quarter, **FAST)
    assert crosstalk_ratio(res["flux"], intended_sai(quarter)) < 0.01
    assert res["flux"][intended_sai(quarter)] == res["flux"].max()


def test_cross_mask_removes_its_geometric_share():
    width_fraction = 1 / 15
    x = np.linspace(-1, 1, 1501)
    xx, yy = np.meshgrid(x, x)
    inside = xx ** 2 + yy ** 2 <= 1
    blocked = inside & ~stop_mask(quarter=None, cross_width_mm=2 * width_fraction)(xx, yy)
    half = width_fraction  # half width of the cross in units of the stop radius
    strip = 2 * (half * math.sqrt(1 - half ** 2) + math.asin(half))  # area of one strip
    expected = (2 * strip - (2 * half) ** 2) / math.pi
    assert blocked.sum() / inside.sum() == pytest.approx(expected, abs=2e-3)
    assert expected == pytest.approx(0.16, abs=0.01)  # the paper: the mask removes 16 %


@pytest.fixture(scope="module")
def table2_report():
    return crosstalk_report(read_lens(ROOT / "configs" / "lenses" / "paper_table2.yaml"), **FAST)


def test_table2_crosstalk_and_the_cross_mask(table2_report):
    rep = table2_report
    assert rep["intended_sai"] == [0, 0]
    flux = np.array(rep["no_mask"]["flux"])
    assert flux[0, 0] == flux.max()
    assert 0.02 < rep["no_mask"]["ratio"] < 0.2  # aberrations leak light off-axis
    assert rep["cross_mask"]["ratio"] < rep["no_mask"]["ratio"]
    assert rep["cross_mask_flux_loss"] == pytest.approx(0.16, abs=0.03)
    assert rep["microlens_pitch_um"] == pytest.approx(2.3981, abs=0.003)  # Table 1's phi
