"""A saved transform or a rig is checked against the views it is applied to (right or refused).

Ground truth: the generator's shifts (plenocli.synth.rig) and the prism camera's own rig
(plenocli.synth.prismcam); the check measures shifts with its own correlation search.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.pipeline.stages.simulate import simulate
from plenocli.stitch import stitch, verify
from plenocli.stitch.rig import PrismRig, ViewOptics
from plenocli.synth.prismcam import Camera, render_dualpixel
from plenocli.synth.rig import make_rig


def _true_transform(truth: dict) -> dict:
    return {"model": "translation", "layout": "1x2", "view_shape": truth["view_shape"],
            "distortion_k1": 0.0, "rig": None,
            "view_to_reference": [np.asarray(m).tolist() for m in truth["relative"]]}


def _dualpixel_pair(focal_mm: float | None = None, *, swapped: bool = False):
    """A simulated dual-pixel + prism pair (views (2, 3, rows, cols), A then B, or B then A)
    and the rig of its camera (``focal_mm``: another focal length)."""
    a, b, truth = render_dualpixel(pixels=384, seed=3, camera=Camera(prism_apex_deg=30.0))
    pair = (b, a) if swapped else (a, b)
    views = np.stack([np.moveaxis(v, -1, 0) for v in pair])
    cam = truth["camera"]
    optics = (ViewOptics((1, 0), (1, 0)), ViewOptics((-1, 0), None))
    rig = PrismRig(cam["focal_mm"] if focal_mm is None else focal_mm, cam["sensor_mm"],
                   cam["prism_n"], cam["prism_apex_deg"], optics, cam["aperture_mm"],
                   cam["object_distance_mm"])
    return views, rig


@pytest.mark.parametrize("overlap", [0.1, 0.3])  # 0.1: a 24 px seam, too narrow for the report
def test_the_residual_of_a_transform_off_by_a_known_shift_is_that_shift(overlap):
    views, _, truth = make_rig(view_shape=(160, 240), overlap=overlap, vignetting=0.1,
                               noise=0.003, seed=4)
    for off, refused in ((0.0, False), (0.3, False), (0.8, True), (3.0, True)):
        t = _true_transform(truth)
        t["view_to_reference"][1][0][2] += off
        if refused:   # before the blend, in the library
            with pytest.raises(ValueError, match="the transform does not describe these views") \
                    as err:
                stitch(views, transform=t)
            measured = float(re.search(r"are ([0-9.]+) px apart", str(err.value)).group(1))
            assert measured == pytest.approx(off, abs=0.1)
        else:
            _, report = stitch(views, transform=t)
            assert [p["residual_px"] for p in report.pairs] == [pytest.approx(off, abs=0.1)]
            assert report.residual_px == pytest.approx(off, abs=0.1)


def test_a_textureless_stretch_of_the_seam_measures_nothing_and_is_left_out():
    """Sky or a wall across part of the seam: the true transform passes, a wrong one is still
    refused by the textured stretch."""
    views, _, truth = make_rig(view_shape=(160, 240), overlap=0.3, vignetting=0.1,
                               noise=0.003, seed=4)
    flat = views.copy()
    noise = np.random.default_rng(1).normal(0.0, 0.003, (2, 80, 100)).astype(np.float32)
    flat[0, :80, 140:] = 0.5 + noise[0]
    flat[1, :80, :100] = 0.5 + noise[1]
    for off, refused in ((0.0, False), (1.5, True)):
        t = _true_transform(truth)
        t["view_to_reference"][1][0][2] += off
        if refused:
            with pytest.raises(ValueError, match="does not describe these views"):
                stitch(flat, transform=t)
        else:
            assert stitch(flat, transform=t)[1].residual_px < 0.1


def test_a_rig_with_the_wrong_focal_length_is_refused():
    for focal, refused in ((None, False), (8.0, True)):
        views, rig = _dualpixel_pair(focal)
        if refused:
            # audit 18 M1: "register without it" alone looped with the registration's "pass
            # the rig" on prism views: the message says the rig is not this capture's
            with pytest.raises(ValueError, match="rig does not describe these views.*not "
                               "this capture's rig"):
                stitch(views, rig=rig)
        else:  # blocks of ~50 px on the chart's mostly vertical texture: 0.2 px of noise
            assert stitch(views, rig=rig)[1].residual_px < 0.25


def test_a_rig_that_warps_prism_free_views_is_refused(tmp_path):
    """A pure-translation pair (no prism) under the dual-pixel prism rig: near the seam's
    middle the wrong warp is nearly a shift, but the fan it makes grows towards the seam's
    ends (1.2 px RMS over the blocks). Without the rig the pair stitches."""
    simulate("stereo-rig", tmp_path / "sr", view_shape=(160, 200), seed=0)
    views = tmp_path / "sr" / "views.tif"
    rig = Path(__file__).resolve().parents[1] / "configs" / "rigs" / "dualpixel_prism.yaml"
    out = tmp_path / "p.tif"
    res = CliRunner().invoke(cli, ["stitch", str(views), "--rig", str(rig), "-o", str(out)])
    assert res.exit_code == 1 and "does not describe these views" in res.output, res.output
    assert not out.exists()
    assert CliRunner().invoke(cli, ["stitch", str(views), "-o", str(out)]).exit_code == 0


def test_a_transform_for_other_views_or_layout_is_refused_in_one_line(tmp_path):
    simulate("stereo-rig", tmp_path / "rig", view_shape=(128, 160), seed=0)
    views = tmp_path / "rig" / "views.tif"
    saved = tmp_path / "t.json"
    assert CliRunner().invoke(cli, ["stitch", str(views), "-o", str(tmp_path / "p.tif"),
                                    "--transform-out", str(saved)]).exit_code == 0
    t = json.loads(saved.read_text())["transform"]
    shifted = json.loads(json.dumps(t))
    shifted["view_to_reference"][1][0][2] += 3.0
    cases = [({**t, "views": ["A", "B"]}, [], "made for views A,B"),
             (t, ["--layout", "2x1"], "--layout 2x1 contradicts"),
             (shifted, [], "does not describe these views")]
    for k, (side, extra, words) in enumerate(cases):
        (tmp_path / f"s{k}.json").write_text(json.dumps({"transform": side}))
        out = tmp_path / f"o{k}.tif"
        res = CliRunner().invoke(cli, ["stitch", str(views), "-o", str(out), "--transform-in",
                                       str(tmp_path / f"s{k}.json"), *extra])
        assert res.exit_code == 1 and words in res.output, (k, res.output)
        assert len(res.output.strip().splitlines()) == 1 and not out.exists()


def test_the_true_quad_pixel_rig_passes_at_every_seam():
    """Four seams, their ends at the panorama's corners where the canvases' edges curve."""
    from plenocli.synth.prismcam import render_quadpixel

    sensor, truth = render_quadpixel(pixels=384, seed=3)
    views = np.stack([np.moveaxis(sensor[i::2, j::2], -1, 0) for i in range(2)
                      for j in range(2)])
    cam = truth["camera"]
    rig = PrismRig(cam["focal_mm"], cam["sensor_mm"], cam["prism_n"], cam["prism_apex_deg"],
                   tuple(ViewOptics(tuple(v["pupil_quarter_xy"]), tuple(v["prism_towards_xy"]))
                         for v in truth["views"]), cam["aperture_mm"], cam["object_distance_mm"])
    _, report = stitch(views, layout="2x2", rig=rig)
    assert max(p["residual_px"] for p in report.pairs) < 0.2


def test_a_block_of_one_direction_s_texture_places_nothing_along_it():
    """Edges along x correlate alike at every shift along x (the aperture problem): that axis
    of the block's shift is unknown (NaN), not a misfit; the other is measured."""
    rng = np.random.default_rng(5)
    yy, xx = np.mgrid[0:64, 0:64].astype(np.float64)

    def stripes(dy):
        return np.sin(0.9 * (yy + dy)) + 0.5 * np.sin(0.37 * (yy + dy) + 1.0)

    a = stripes(0.0) + rng.normal(0, 0.01, yy.shape)
    b = stripes(0.3) + rng.normal(0, 0.01, yy.shape)
    shift, corr = verify._block_shift(a, b, np.ones(a.shape, bool))
    assert abs(shift[0] + 0.3) < 0.05 and np.isnan(shift[1]) and corr > 0.95
    spots = np.sin(0.9 * yy) * np.sin(0.7 * xx) + rng.normal(0, 0.01, yy.shape)
    shift, _ = verify._block_shift(spots, spots, np.ones(a.shape, bool))
    assert np.all(np.abs(shift) < 0.05)


def test_a_rig_refused_under_a_users_distortion_names_the_distortion():
    """audit 9 E10: with --distortion the rig's check blamed the rig, which stitches these
    views without it."""
    from plenocli.pipeline.stages.stitch import _claim

    views, rig = _dualpixel_pair()
    with pytest.raises(ValueError, match=r"the rig r.yaml on views with --distortion 0.05 "
                                         r"removed does not describe these views.*check "
                                         r"--distortion, or leave it out"):
        stitch(views, rig=rig, distortion_k1=0.05, claim=_claim(None, "r.yaml", 0.05))


def _masked_ncc(a, b, valid):
    """The seam check's correlations by their definition, in float64 (0 where a side is flat)."""
    s = verify.SEARCH_PX
    rows, cols = a.shape
    x = a[s:rows - s, s:cols - s][valid].astype(np.float64)
    x -= x.mean()
    out = np.zeros((2 * s + 1, 2 * s + 1))
    for dy in range(-s, s + 1):
        for dx in range(-s, s + 1):
            y = b[s + dy:rows - s + dy, s + dx:cols - s + dx][valid].astype(np.float64)
            y -= y.mean()
            den = np.sqrt((x * x).sum() * (y * y).sum())
            out[dy + s, dx + s] = (x * y).sum() / den if den > 0 else 0.0
    return out


@pytest.mark.parametrize("case", ["all valid", "masked", "flat template", "flat view"])
def test_the_seam_correlations_are_the_masked_ncc(case):
    rng = np.random.default_rng(3)
    a = rng.normal(size=(64, 72)).astype(np.float32)
    b = np.roll(a, (1, -2), (0, 1)) + rng.normal(0, 0.1, a.shape).astype(np.float32)
    valid = np.ones((64 - 8, 72 - 8), bool)
    if case != "all valid":
        valid[:20, :15] = False
    if case == "flat template":
        a[:] = 0.5
    if case == "flat view":
        b[:] = 0.25
    np.testing.assert_allclose(verify._scores(a, b, valid), _masked_ncc(a, b, valid), atol=1e-5)


def test_a_seam_without_texture_cannot_vouch_for_a_transform():
    """Round 11 W1: an overlap made constant (a noise-free sky) correlated the float32 rounding
    of its resampling at 0.51 and passed a transform 8 px off, residual 0.05 px. A constant
    block measures nothing; a seam of nothing else leaves the transform unvouched: refused,
    the true one too (nothing there can tell it from a wrong one)."""
    views, _, truth = make_rig(view_shape=(160, 240), overlap=0.3, vignetting=0.0, noise=0.0,
                               seed=4)
    flat = views.copy()
    flat[0, :, 150:] = 0.5
    flat[1, :, :90] = 0.5
    for off in (0.0, 8.0):
        t = _true_transform(truth)
        t["view_to_reference"][1][0][2] += off
        with pytest.raises(ValueError, match="no overlap large enough, and textured, to check"):
            stitch(flat, transform=t)


def test_views_in_another_order_than_the_rigs_are_told_so():
    """audit 18 M4: the right rig with the views swapped was refused as "no reliable overlap
    ... or the overlap has no texture" alone, though the pair overlaps and is textured."""
    views, rig = _dualpixel_pair(swapped=True)
    with pytest.raises(ValueError, match="not in the rig's order"):
        stitch(views, rig=rig)
