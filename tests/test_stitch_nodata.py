"""NaN (clipped or unknown) pixels in the views: isolated ones cost only themselves
(plenocli.stitch.nodata); a view too unknown to place is refused naming its NaN."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.stitch import StitchError, stitch
from plenocli.stitch.nodata import NoData
from plenocli.synth.rig import make_rig


def _sprinkled(views: np.ndarray, fraction: float, seed: int = 1) -> tuple[np.ndarray, tuple]:
    """A copy of ``views`` with ``fraction`` of view 1's pixels NaN, scattered, plus a dead row
    and a dead column of it (a clipped or hot pixel, a dead line: what bias writes as NaN)."""
    out = views.astype(np.float32).copy()
    rng = np.random.default_rng(seed)
    out[1][rng.random(out[1].shape) < fraction] = np.nan
    out[1][:, 200] = np.nan
    out[1][150, :] = np.nan
    return out, np.nonzero(np.isnan(out[1]))


@pytest.mark.parametrize("how", ["registered", "transform", "homography"])
def test_scattered_nan_pixels_cost_only_themselves(how):
    """Audit 18 F2: 1 % of a view's pixels NaN, scattered, was refused however the views were
    placed ("no overlap large enough, and textured, to check ...: give the rig"), since each
    NaN took its neighbourhood out of the registration, the seam check and the feather."""
    views, _, _ = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.3, seed=6)
    model = "homography" if how == "homography" else "auto"
    clean, report0 = stitch(views, model=model)
    sprinkled, (ys, xs) = _sprinkled(views, 0.01)
    transform = report0.transform if how == "transform" else None
    pano, report = stitch(sprinkled, model=model, transform=transform)
    assert pano.shape == clean.shape and report.origin_px == report0.origin_px
    moved = np.abs(np.array(report.shifts_px) - np.array(report0.shifts_px)).max()
    assert moved < (0.02 if how != "homography" else 0.05)
    assert np.allclose(report.gains, report0.gains, rtol=2e-3)
    assert report.pairs[0]["residual_px"] < 0.1
    # each NaN pixel stays no data: NaN where view 1 covers the panorama alone, view 0's in
    # the overlap (a pixel or two of its resampling footprint, not its neighbourhood)
    dy, dx = report.shifts_px[1]
    py = np.round(ys + dy + report.origin_px[0]).astype(int)
    px = np.round(xs + dx + report.origin_px[1]).astype(int)
    y0, x0 = py - report.origin_px[0], px - report.origin_px[1]  # in view 0's pixels
    inside = (y0 >= 2) & (y0 <= 197) & (x0 >= 2) & (x0 <= 257)
    alone = (y0 < -2) | (y0 > 201) | (x0 > 261)
    assert alone.sum() > 200 and inside.sum() > 50
    assert np.isnan(pano[py[alone], px[alone]]).all()
    assert np.isfinite(pano[py[inside], px[inside]]).all()
    newly_nan = np.isnan(pano) & np.isfinite(clean)
    assert newly_nan.sum() <= 4 * alone.sum()
    # elsewhere the panorama is the clean one's: the feather is not pulled down around them
    far = np.isfinite(pano) & np.isfinite(clean)
    assert np.median(np.abs(pano - clean)[far]) < 1e-5


def test_a_view_too_unknown_to_place_is_refused_naming_its_nan():
    """Every other column NaN: no NaN pixel has half of its neighbours known, so nothing of the
    view can be measured; the refusal says so, not "give the rig / the overlap"."""
    views, _, _ = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.3, seed=6)
    views = views.astype(np.float32)
    views[1][:, ::2] = np.nan
    with pytest.raises(StitchError, match="view 1 has 50 % of its pixels unknown") as err:
        stitch(views)
    assert "--rig" not in str(err.value) and "--overlap" not in str(err.value)


def test_isolated_nan_pixels_are_estimated_holes_are_kept():
    """A NaN pixel with half of the 5 x 5 around it known is estimated (exactly, on a ramp);
    the inside of a larger hole is not, and only holes pull the feather's weight down."""
    ramp = np.add.outer(np.arange(40.0), 2 * np.arange(50.0)).astype(np.float32)
    stack = np.stack([ramp, ramp])[:, np.newaxis].copy()
    stack[1, 0, 10, 10] = np.nan           # a hot pixel
    stack[1, 0, 20, :] = np.nan            # a dead row
    stack[1, 0, 28:36, 30:40] = np.nan     # a clipped area
    nodata = NoData(stack)
    measured = nodata.measured(stack)
    assert measured is not stack and np.isnan(stack[1, 0, 10, 10])  # the input is kept
    assert nodata.valid[0] is None and nodata.holes()[0] is None
    assert measured[1, 0, 10, 10] == pytest.approx(ramp[10, 10], abs=1e-4)
    assert np.allclose(measured[1, 0, 20, 2:-2], ramp[20, 2:-2], atol=1e-4)
    assert np.isnan(measured[1, 0, 31:33, 33:37]).all()
    valid, distance = nodata.holes()[1]
    assert valid[10, 10] == 0 and valid[20, 5] == 0
    assert distance[10, 10] > 5 and distance[20, 5] > 5 and distance[32, 35] == 0
