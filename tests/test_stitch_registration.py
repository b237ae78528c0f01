"""The registration's parallel pairs and the photometric refinement's choice of points."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy import ndimage

from plenocli.stitch import StitchError, photometric, registration, stitch
from plenocli.synth.rig import make_rig


def test_the_strongest_pixels_are_the_textured_ones_inside_the_overlap():
    rng = np.random.default_rng(4)
    a = np.full((120, 160), 0.5, np.float32)
    a[:, 80:] += ndimage.gaussian_filter(rng.standard_normal((120, 80)), 1.5).astype(np.float32)
    cover = np.zeros(a.shape, bool)
    cover[4:-4, 4:-4] = True
    cover[:, 120:] = False  # textured, but outside the overlap
    count = 2000
    kept = photometric._strongest(a, cover, count)
    assert np.count_nonzero(kept) == count
    assert not (kept & ~cover).any()
    assert not kept[:, :79].any()  # the flat half holds no information


def test_the_refinement_points_hold_most_of_the_information():
    """A quarter of the overlap's pixels, those of strongest gradient, hold most of the
    Gauss-Newton information on the shift (the trace of its Hessian); a random quarter holds a
    quarter of it. For a band-limited texture (gradient components Gaussian, squared norm
    exponential) the strongest quarter holds 1/4 (1 + ln 4) = 60 %."""
    views, _, truth = make_rig(layout="1x2", model="homography", view_shape=(300, 400),
                               overlap=0.3, perspective_px=4.0, seed=11)
    a, h = views[0].astype(np.float32), np.array(truth["relative"][1])
    *_, every = photometric._template(a, None, None, views[1].shape, h, 10**9)
    *_, strongest = photometric._template(a, None, None, views[1].shape, h,
                                          every.shape[1] // 4)
    info = [float(np.sum(s[2].astype(np.float64) ** 2 + s[5].astype(np.float64) ** 2))
            for s in (every, strongest)]
    assert abs(strongest.shape[1] - every.shape[1] // 4) <= 1
    assert 0.55 < info[1] / info[0] < 0.65  # measured 0.593


def test_pairs_registered_in_threads_are_those_registered_one_after_another(monkeypatch):
    views, _, _ = make_rig(layout="2x2", model="homography", view_shape=(300, 400),
                           overlap=0.3, perspective_px=3.0, noise=0.003, seed=2)
    _, together = stitch(views, layout="2x2", model="homography")
    monkeypatch.setattr(registration, "PAIR_THREADS", 1)
    _, serial = stitch(views, layout="2x2", model="homography")
    assert together.transform == serial.transform
    assert together.pairs == serial.pairs


def test_a_refusal_is_that_of_the_first_pair_in_order(monkeypatch):
    """The pairs run at once, but the one refused first in the layout's order is reported,
    whichever thread finishes first."""
    def measure(images, a, b, *args):
        if (a, b) == (0, 1):
            time.sleep(0.3)
        raise StitchError(f"views {a} and {b}: refused")

    monkeypatch.setattr(registration, "_measure_pair", measure)
    luma = np.zeros((4, 60, 80), np.float32)
    expected = {pair: (None, None) for pair in ((0, 1), (0, 2), (1, 3), (2, 3))}
    with pytest.raises(StitchError, match="views 0 and 1"):
        registration.register(lambda a, b, _: (luma[a], luma[b], (0, 0), (0, 0)), 4, (60, 80),
                              "2x2", "translation", {}, expected)


@pytest.mark.parametrize("model", ["translation", "homography"])
@pytest.mark.parametrize("scale,which", [(1e-9, "all"), (1e-12, "all"), (1e12, "all"),
                                         (2.0, "one"), (1e-6, "one"), (1e-12, "one")])
def test_the_views_unit_and_exposure_do_not_move_the_match(model, scale, which):
    # audit 12: views x 1e-9 were registered 0.37 px off (exit 0), x 1e12 and 1e-12 refused
    # ("no reliable overlap"), one view x 1e-6 refused ("has no texture"), one view x 2 moved
    # 0.04 px: the floors of the fits and of the texture checks were absolute
    views, _, _ = make_rig(layout="2x2", model=model, view_shape=(200, 260), overlap=0.3,
                           perspective_px=3.0, noise=0.003, seed=12)
    _, plain = stitch(views, layout="2x2", model=model)
    scaled = views.astype(np.float64)
    scaled[slice(None) if which == "all" else 1] *= scale
    _, report = stitch(scaled.astype(np.float32), layout="2x2", model=model)
    for before, after in zip(plain.transform["view_to_reference"],
                             report.transform["view_to_reference"], strict=True):
        corners = np.float64([[0, 0, 1], [259, 0, 1], [0, 199, 1], [259, 199, 1]]).T
        moved = [np.asarray(m) @ corners for m in (before, after)]
        moved = [p[:2] / p[2] for p in moved]
        assert np.abs(moved[0] - moved[1]).max() < 0.005
    assert report.gains[1][0] == pytest.approx(plain.gains[1][0] / (scale if which == "one"
                                                                    else 1.0), rel=1e-3)


def test_an_overlap_with_nothing_known_is_not_reported_as_a_correlation_of_minus_one():
    """Audit 12 E1: views whose overlap is all NaN were refused with "best normalised
    correlation -1.00 < 0.4": -1 is the search's mark for a shift with nothing to correlate,
    and read as perfectly anti-correlated views."""
    from plenocli.stitch.translation import estimate_translation

    views, _, _ = make_rig(layout="1x2", view_shape=(120, 160), overlap=0.3, jitter_px=0,
                           seed=4)
    a, b = views[0].copy(), views[1].copy()
    a[:, 30:] = np.nan  # every shift within max_overlap sees only NaN of view a
    with pytest.raises(StitchError, match="nothing to correlate") as err:
        estimate_translation(a, b, direction="h")
    assert "-1.00" not in str(err.value) and "NaN" in str(err.value)


@pytest.mark.parametrize("which, refused", [(0, True), (1, False)])
def test_views_brought_below_float32s_normal_range_are_refused(which, refused):
    """audit 18 W7: view 0 at 1e-38 (a subnormal level) made every gain match down to it, and
    the panorama held zeros where a bright view alone covered it, exit 0. One view that dark
    is matched up to the others instead; the panorama's level set by such a view is refused."""
    views, _, _ = make_rig(layout="2x2", model="translation", view_shape=(200, 260),
                           overlap=0.3, noise=0.003, seed=12)
    scaled = views.astype(np.float64)
    scaled[which] *= 1e-38 / np.median(np.abs(views[which]))
    scaled = scaled.astype(np.float32)
    if refused:
        with pytest.raises(StitchError, match="view 0 has a level of .* below float32's normal"):
            stitch(scaled, layout="2x2", model="translation")
        stitch(scaled, layout="2x2", model="translation", match_gain=False)
    else:
        panorama, _ = stitch(scaled, layout="2x2", model="translation")
        plain, _ = stitch(views, layout="2x2", model="translation")
        covered = np.isfinite(plain)
        assert np.array_equal(np.isfinite(panorama), covered)
        assert np.abs(panorama[covered] - plain[covered]).max() < 1e-3
