"""Golden test: the shipped dual-pixel fixture through decode -> bias, against its ground truth
(fixtures/dualpixel/truth.npz: the noise-free views above black, the clipped pixels and the
per-row bias the generator added; truth.json: its noise level)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io.tiffio import read_image
from tests.conftest import FIXTURES

FOLDER = FIXTURES / "dualpixel"
TOLERANCE_DN = 0.5


@pytest.fixture(scope="module")
def biased(tmp_path_factory):
    out = tmp_path_factory.mktemp("golden")
    runner = CliRunner()
    for args in (["decode", FOLDER / "capture.dng", "-o", out / "frames.tif"],
                 ["bias", out / "frames.tif", "--smooth", "9", "-o", out / "biased.tif"]):
        result = runner.invoke(cli, [str(a) for a in args])
        assert result.exit_code == 0, result.output
    return read_image(out / "biased.tif")


@pytest.fixture(scope="module")
def truth():
    doc = json.loads((FOLDER / "truth.json").read_text())["captures"]["capture"]
    return doc, dict(np.load(FOLDER / "truth.npz"))


def test_views_frame_and_cfa(biased, truth):
    views, meta = biased
    doc, _ = truth
    geometry = doc["geometry"]
    assert meta["views"] == ["A", "B", "S"]
    assert views.shape == (3, geometry["rows"], geometry["cols"])
    assert meta["origin"] == [geometry["top"], geometry["left"]]
    assert meta["cfa"] == geometry["cfa"]  # even margins keep the CFA phase


def test_measured_row_bias_within_half_a_dn(biased, truth):
    _, meta = biased
    doc, arrays = truth
    top, bottom = doc["geometry"]["active_area"][0], doc["geometry"]["active_area"][2]
    for k, levels in enumerate(meta["bias_levels"]):
        measured = np.asarray(levels["row_levels"])
        expected = arrays["capture_row_bias"][k][top:bottom]
        assert levels["mode"] == "left"
        assert np.abs(measured - expected).max() < TOLERANCE_DN, levels["frame"]


@pytest.mark.parametrize("view", ["A", "B", "S"])
def test_views_match_the_truth_within_the_noise(biased, truth, view):
    views, meta = biased
    doc, arrays = truth
    got = views[meta["views"].index(view)]
    expected = arrays[f"capture_{view}"]
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))  # clipped pixels masked
    error = (got - expected)[np.isfinite(expected)]
    assert abs(error.mean()) < TOLERANCE_DN
    # what is left is the sensor noise: B = S - A carries the noise of both frames
    noise = doc["params"]["noise"] * (np.sqrt(2.0) if view == "B" else 1.0)
    assert error.std() == pytest.approx(noise, rel=0.05)


def test_clipped_pixels_follow_the_truth(biased, truth):
    views, meta = biased
    _, arrays = truth
    a, b, s = (views[meta["views"].index(v)] for v in "ABS")
    np.testing.assert_array_equal(np.isnan(s), arrays["capture_clipped_S"])
    np.testing.assert_array_equal(np.isnan(b),
                                  arrays["capture_clipped_S"] | arrays["capture_clipped_A"])
    assert arrays["capture_clipped_S"].any()  # the fixture does exercise clipping
