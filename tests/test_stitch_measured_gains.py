"""Exposure gains from measured values only (audit 13 W2): a Bayer view's channels rebuilt
around clipped or unknown photosites (plenocli.colour.highlights, an estimate floored at the
clip level) are left out of the overlap sums; a channel a view measured too little of is
refused, naming the view and the colour."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.colour.highlights import Estimated
from plenocli.stitch.errors import StitchError
from plenocli.stitch.overlaps import Overlap, match_gains
from plenocli.stitch.panorama import stitch
from plenocli.synth.rig import make_rig
from tests.bad_inputs.files import assert_one_line, plenocli_tiff, run_bad

GAINS = (1.05, 0.97, 1.02)  # view B's exposure against view A's, per colour
SHIFT = 96  # view B starts this far right in the scene (even: the same CFA phase)


def _capture(seed: int = 3, rows: int = 192, cols: int = 256) -> np.ndarray:
    """Two RGGB views (2, rows, cols) of one textured scene with bright patches, B shifted
    SHIFT px and exposed GAINS times A, with a little noise; no offset, so every part of the
    overlap gives B's gains."""
    rng = np.random.default_rng(seed)
    width = cols + SHIFT
    base = cv2.GaussianBlur(rng.random((rows, width)).astype(np.float32), (0, 0), 3) * 4
    tint = np.stack([cv2.GaussianBlur(rng.random((rows, width)).astype(np.float32), (0, 0),
                                      12) for _ in range(3)])
    scene = np.exp(base - base.mean()) * (0.6 + tint)
    scene *= 1000 / np.median(scene)
    views = []
    for k, gains in enumerate(((1, 1, 1), GAINS)):
        rgb = scene[:, :, k * SHIFT:k * SHIFT + cols] * np.array(gains)[:, None, None]
        mosaic = np.empty((rows, cols), np.float32)
        for (dy, dx), c in zip(((0, 0), (0, 1), (1, 0), (1, 1)), (0, 1, 1, 2), strict=True):
            mosaic[dy::2, dx::2] = rgb[c, dy::2, dx::2]
        views.append(mosaic + rng.normal(0, 2, mosaic.shape).astype(np.float32))
    return np.stack(views)


def _views_file(tmp_path, views: np.ndarray, name: str):
    folder = tmp_path / name
    folder.mkdir()
    plenocli_tiff(folder / "views.tif", views, cfa="RGGB", views=["A", "B"])
    return folder


def _gains(tmp_path, views: np.ndarray, name: str, *extra: str) -> np.ndarray:
    """View B's gains as the stitch of ``views`` (a file) reports them."""
    folder = _views_file(tmp_path, views, name)
    result = CliRunner().invoke(cli, ["stitch", str(folder / "views.tif"), "--layout", "1x2",
                                      "-o", str(folder / "p.tif"), "--report",
                                      str(folder / "r.json"), *extra])
    assert result.exit_code == 0, result.output + result.stderr
    return np.array(json.loads((folder / "r.json").read_text())["gains"][1])


@pytest.fixture(scope="module")
def clean_gains(tmp_path_factory):
    return _gains(tmp_path_factory.mktemp("clean"), _capture(), "clean")


def test_clipped_highlights_leave_the_gains_as_the_unclipped_captures(tmp_path, clean_gains):
    """Every photosite above a clip level NaN in both views (9 % of A, 11 % of B, in bright
    patches): the rebuilt channels, floored at the clip level, pulled B's gains 0.3 % (R) and
    0.2 % (B) off; measured pixels only, they stay within 0.02 %."""
    assert np.allclose(clean_gains, 1 / np.array(GAINS), rtol=2e-4)
    views = _capture()
    views[views > np.percentile(views, 90)] = np.nan
    assert np.allclose(_gains(tmp_path, views, "clipped"), clean_gains, rtol=2e-4)


def test_scattered_unknown_photosites_leave_the_gains_as_measured(tmp_path, clean_gains):
    """1 % of view B's photosites NaN, scattered: each pixel around one has that colour
    rebuilt; left out, B's gains stay those of the clean capture."""
    views = _capture()
    views[1][np.random.default_rng(5).random(views[1].shape) < 0.01] = np.nan
    assert np.allclose(_gains(tmp_path, views, "scattered"), clean_gains, rtol=2e-4)


def test_a_colour_measured_nowhere_in_the_overlap_is_refused_naming_the_view(tmp_path):
    """View A's red NaN but one photosite (audit 13 W2): its red is rebuilt from green and
    blue everywhere, and the gain was taken from it (R 1.118, exit 0); refused, naming the
    view and the colour; --gains none stitches it as recorded."""
    views = _capture()
    views[0, 0::2, 0::2] = np.nan
    views[0, 100, 30] = 500.0
    result = run_bad(_views_file(tmp_path, views, "red"), tmp_path / "out",
                     ["stitch", "{i}/views.tif", "--layout", "1x2", "-o", "{o}/p.tif"])
    assert_one_line(result, 1, ("view 0's red is measured in none of its overlap with view 1",
                                "--gains none"))
    assert np.allclose(_gains(tmp_path, views, "none", "--gains", "none"), 1.0)


def test_a_channel_is_matched_through_the_other_overlaps():
    """2 x 2: the pair (0, 1) measured no red, but view 1 is reached through views 2 and 3:
    its red gain comes from those overlaps, not refused."""
    pairs = [(0, 1, "h"), (2, 3, "h"), (0, 2, "v"), (1, 3, "v")]
    means = np.array([[1.0, 1.0, 1.0], [0.5, 0.8, 2.0], [1.0, 1.0, 1.0], [0.5, 0.8, 2.0]])

    def overlap(a, b, red):
        counts = np.array([red, 5000, 5000])
        flat = np.stack([means[a] ** 2, means[b] ** 2, means[a] * means[b]]) * counts
        return Overlap(np.stack([means[a], means[b]]) * counts, counts,
                       np.array([[5000] * 3, [red, 5000, 5000]]), 5000, 5000, flat)

    overlaps = [overlap(0, 1, 0), overlap(2, 3, 5000), overlap(0, 2, 5000),
                overlap(1, 3, 5000)]
    gains = match_gains(overlaps, pairs, np.ones((4, 3, 8, 8), np.float32))
    assert np.allclose(gains, 1 / means)
    overlaps[3] = overlap(1, 3, 10)
    with pytest.raises(StitchError, match="view 1's red is measured in none of its overlap"):
        match_gains(overlaps, pairs, np.ones((4, 3, 8, 8), np.float32))


def test_estimated_channels_are_kept_in_bits():
    rng = np.random.default_rng(2)
    truth = rng.random((3, 70, 83)) < 0.2
    truth[0] = False  # a channel never estimated holds nothing
    rows, cols = np.nonzero(truth.any(axis=0))
    marks = Estimated((70, 83))
    marks.mark(rows, cols, truth[:, rows, cols].T)
    assert marks.bits[0] is None and marks.region(0, slice(0, 70), slice(0, 83)) is None
    for c in (1, 2):
        assert (marks.region(c, slice(0, 70), slice(0, 83)) == truth[c]).all()
        assert (marks.region(c, slice(5, 40), slice(13, 61)) == truth[c, 5:40, 13:61]).all()


@pytest.mark.parametrize("offset,gain,refused", [(0.3, 1.0, True), (0.15, 0.5, True),
                                                 (0.0, 0.7, False), (0.005, 1.0, False)])
def test_views_that_differ_by_an_offset_are_refused_not_given_a_gain(offset, gain, refused):
    """audit 24 W1: a view with an offset left in (a black level not subtracted) got a gain
    (3.07 for views of one exposure, 0.3 of the level apart: the panorama 34 % too bright).
    A gain leaves many times the residual a gain and an offset do: refused. A gain alone, with
    vignetting and noise, and an offset too small to move the gain by 2 % are taken."""
    views, _, truth = make_rig(layout="1x2", view_shape=(300, 400), overlap=0.3,
                               vignetting=0.1, noise=0.003, seed=3)
    views = np.array(views)
    before = stitch(views, layout="1x2")[1].gains[1][0]
    views[1] = views[1] * gain - offset
    if refused:
        with pytest.raises(StitchError, match="views 0 and 1 differ by an offset, not by an "
                                              "exposure gain"):
            stitch(views, layout="1x2")
    else:
        _, report = stitch(views, layout="1x2")
        assert abs(report.gains[1][0] * gain / before - 1) < (0.02 if offset else 1e-4)
