"""Prism distortion model and prior-guided stitching of the paper's rigs, against the simulator's
ground truth (plenocli.synth.prismcam)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.stitch import (
    PrismRig,
    StitchError,
    ViewOptics,
    common_to_view,
    estimate_translation,
    stitch,
    view_to_common,
)
from plenocli.synth.prismcam import Camera, render_dualpixel, render_quadpixel


def rig_from_truth(truth: dict, views: list[ViewOptics]) -> PrismRig:
    cam = truth["camera"]
    return PrismRig(cam["focal_mm"], cam["sensor_mm"], cam["prism_n"], cam["prism_apex_deg"],
                    tuple(views), cam["aperture_mm"], cam["object_distance_mm"])


def quad(pixels):
    sensor, truth = render_quadpixel(pixels=pixels, seed=3)
    views = np.stack([np.moveaxis(sensor[i::2, j::2], -1, 0) for i in range(2)
                      for j in range(2)])
    rig = rig_from_truth(truth, [ViewOptics(tuple(v["pupil_quarter_xy"]),
                                            tuple(v["prism_towards_xy"])) for v in truth["views"]])
    return views, truth, rig


def dual(pixels):
    a, b, truth = render_dualpixel(pixels=pixels, seed=3, camera=Camera(prism_apex_deg=30.0))
    rig = rig_from_truth(truth, [ViewOptics((1, 0), (1, 0)), ViewOptics((-1, 0), None)])
    return np.stack([np.moveaxis(a, -1, 0), np.moveaxis(b, -1, 0)]), truth, rig


def red_disc(pano, near_rc, window=15):
    """Centroid [row, col] of the saturated red axis marker near ``near_rc``."""
    r, g, b = (np.nan_to_num(pano[k]) for k in range(3))
    top = 1.0  # chart white (Lanczos overshoot makes the maximum larger)
    mask = (r > 0.7 * top) & (g < 0.3 * top) & (b < 0.3 * top)
    yy, xx = np.mgrid[0:r.shape[0], 0:r.shape[1]]
    mask &= (np.abs(yy - near_rc[0]) < window) & (np.abs(xx - near_rc[1]) < window)
    return np.array([yy[mask].mean(), xx[mask].mean()]), int(mask.sum())


@pytest.mark.parametrize("distance", [2000.0, math.inf])
@pytest.mark.parametrize("view", [ViewOptics((1, 1), (1, 1)), ViewOptics((-1, 0), None),
                                  ViewOptics((1, 0), (1, 0))])
def test_inverse_is_exact(distance, view):
    rig = PrismRig(6.16, 3.6, 1.74, 16.7, (view,), 3.09, distance)
    yy, xx = np.mgrid[0:200:7, 0:300:11].astype(float)
    cx, cy = view_to_common(rig, 0, xx, yy, (200, 300))
    bx, by = common_to_view(rig, 0, cx, cy, (200, 300))
    assert np.abs(bx - xx).max() < 1e-8 and np.abs(by - yy).max() < 1e-8


@pytest.mark.parametrize("apex_deg", [30.0, 60.0])
def test_interpolated_maps_agree_with_tracing_every_pixel(apex_deg):
    """The remap maps, traced on a node grid and interpolated, equal the per-pixel tracing
    within one float32 step of the coordinates (+ 2e-6 px near 0); where no ray gets through
    is the same. At 60 deg almost half the canvas is lost to total reflection."""
    from plenocli.stitch.rig import _view_maps

    rig = PrismRig(50.0, 36.0, 1.5, apex_deg, (ViewOptics((1, 0), (1, 0)),),
                   aperture_mm=10.0)
    shape, canvas, origin = (683, 1024), (720, 1100), np.array([-40.0, -17.0])  # pitch 4 px
    maps = list(_view_maps(rig, 0, origin, canvas, shape))
    mx, my, bad = (np.concatenate([m[i] for m in maps]) for i in (1, 2, 3))
    gy, gx = np.mgrid[0:canvas[0], 0:canvas[1]].astype(np.float64)
    ex, ey = common_to_view(rig, 0, gx + origin[0], gy + origin[1], shape)
    lost = ~(np.isfinite(ex) & np.isfinite(ey))
    np.testing.assert_array_equal(bad, lost)
    for got, want in ((mx, ex), (my, ey)):
        step = np.spacing(np.abs(want[~lost]).astype(np.float32))
        assert np.all(np.abs(got[~lost] - want[~lost]) <= step + 2e-6)


def test_no_prism_at_infinity_is_identity():
    rig = PrismRig(6.16, 3.6, 1.74, 16.7, (ViewOptics((1, 0), None),))
    yy, xx = np.mgrid[0:50:5, 0:80:7].astype(float)
    cx, cy = view_to_common(rig, 0, xx, yy, (50, 80))
    assert np.allclose(cx, xx, atol=1e-9) and np.allclose(cy, yy, atol=1e-9)


def test_model_maps_view_centres_where_the_simulator_traced_them():
    _, truth, rig = quad(256)
    cols = 128
    pix = rig.sensor_mm / cols
    for k, v in enumerate(truth["views"]):
        cx, cy = view_to_common(rig, k, np.array([(cols - 1) / 2]), np.array([(cols - 1) / 2]),
                                (cols, cols))
        expected = -np.array(v["centre_mm"]) * truth["image_distance_mm"] \
            / rig.object_distance_mm / pix + (cols / 2 - 0.5)
        assert np.allclose([cx[0], cy[0]], expected, atol=1e-6)


def check_rig_panorama(pano, rep, expected_field_deg, *, corr=0.95, residual=0.25):
    axis = np.array(rep.axis_px)
    found, area = red_disc(pano, axis)
    assert area > 8
    assert np.linalg.norm(found - axis) < 1.0  # the axis marker lands where the truth says
    for p in rep.pairs:  # exact rig model: the registration only confirms the prediction
        assert np.allclose(p["shift_px"], p["expected_shift_px"], atol=0.1)
        assert p["correlation"] > corr  # no ghosting over the overlap
    assert rep.residual_px is not None and rep.residual_px < residual
    for axis_name, deg in expected_field_deg.items():
        assert rep.field_deg[axis_name] == pytest.approx(deg, abs=1.5)


def test_quadpixel_pyramid_stitches_to_twice_the_field():
    views, truth, rig = quad(512)
    pano, rep = stitch(views, layout="2x2", rig=rig)
    main = truth["main_lens_field_deg"]
    field = truth["stitched_field_deg"]
    assert field["x"] == pytest.approx(2 * main, abs=1.5)  # 32 -> 64 deg
    check_rig_panorama(pano, rep, {"x": field["x"], "y": field["y"]})


@pytest.mark.parametrize("pixels", [384, 576])
def test_dualpixel_prism_stitches_where_translation_alone_failed(pixels):
    views, truth, rig = dual(pixels)
    pano, rep = stitch(views, layout="1x2", rig=rig)
    check_rig_panorama(pano, rep, {"x": truth["stitched_field_x_deg"]})


def test_transform_with_rig_is_reapplied():
    views, _, rig = dual(384)
    pano, rep = stitch(views, layout="1x2", rig=rig)
    again, rep2 = stitch(views * 0.5, transform=rep.transform)
    assert rep2.transform_source == "given" and rep2.rig == rig.to_dict()
    assert np.allclose(np.nan_to_num(again), np.nan_to_num(pano) * 0.5, atol=1e-5)


def test_a_second_capture_of_one_transform_traces_no_ray_again(monkeypatch):
    """A batch stitched by one transform maps the same canvases of the same rig: the second
    capture's maps come from the traced node grids of the first (bounded), bit for bit."""
    from plenocli.stitch import rig as rig_module

    views, _, rig = dual(384)
    _, rep = stitch(views, layout="1x2", rig=rig)
    first, _ = stitch(views, transform=rep.transform)
    traced = []
    real = rig_module._traced
    monkeypatch.setattr(rig_module, "_traced", lambda *a: traced.append(a) or real(*a))
    again, _ = stitch(views, transform=rep.transform)
    assert not traced and np.array_equal(again, first, equal_nan=True)
    held = sum(a.nbytes for g in rig_module._NODE_CACHE.values() for a in (*g[0], *g[1:]))
    assert 0 < held <= rig_module.NODE_CACHE_BYTES


@pytest.mark.parametrize("blend", ["feather", "multiband"])
def test_interleaved_colour_views_give_the_planar_panorama_bit_for_bit(blend):
    """Views whose channels are interleaved in memory (as the stage demosaics them) are
    resampled by one multi-channel remap; the panorama must be that of planar views."""
    views, _, rig = dual(384)
    interleaved = np.moveaxis(np.ascontiguousarray(np.moveaxis(views, 1, -1)), -1, 1)
    assert not interleaved.flags.c_contiguous and np.array_equal(interleaved, views)
    pano, rep = stitch(views, layout="1x2", rig=rig, blend=blend)
    pano_i, rep_i = stitch(interleaved, layout="1x2", rig=rig, blend=blend)
    assert np.array_equal(pano, pano_i, equal_nan=True)
    assert rep.shifts_px == rep_i.shifts_px and rep.gains == rep_i.gains


def test_periodic_scene_is_refused_not_ghosted():
    rng = np.random.default_rng(4)
    from scipy import ndimage

    tile = ndimage.gaussian_filter(rng.random((40, 40)), 2.0, mode="wrap")
    scene = np.tile(tile, (4, 12))  # period 40 px in both directions
    a, b = scene[:, :260], scene[:, 200:460]
    with pytest.raises(StitchError, match="ambiguous"):
        estimate_translation(a, b, direction="h")


def test_homography_on_the_quadpixel_chart_without_a_rig_is_refused_not_ghosted():
    """The chart's grid lets SIFT lay every view on top of the others; that must be an error."""
    views, _, _ = quad(512)
    with pytest.raises(StitchError, match="false match|ambiguous|no reliable"):
        stitch(views, layout="2x2", model="homography")


def test_overlap_prior_restricts_the_search():
    rng = np.random.default_rng(5)
    from scipy import ndimage

    scene = ndimage.gaussian_filter(rng.random((160, 500)), 2.0)
    a, b = scene[:, :300], scene[:, 240:]  # 60 px = 20 % overlap
    dy, dx, _ = estimate_translation(a, b, prior=(0.0, 300 * 0.8), tolerance_px=10)
    assert abs(dy) < 0.05 and abs(dx - 240) < 0.05


def test_cli_rig_file_and_errors(tmp_path):
    from plenocli.io import tiffio

    views, _, rig = dual(384)
    meta = {"views": [f"{v}.{c}" for v in "AB" for c in "RGB"]}
    src = tmp_path / "views.tif"
    tiffio.write_image(src, views.reshape(6, *views.shape[2:]).astype(np.float32), meta)
    rig_file = tmp_path / "rig.json"
    rig_file.write_text(json.dumps(rig.to_dict()))
    out, report = tmp_path / "pano.tif", tmp_path / "rep.json"
    res = CliRunner().invoke(cli, ["stitch", str(src), "--layout", "1x2", "--rig", str(rig_file),
                                   "-o", str(out), "--report", str(report)])
    assert res.exit_code == 0, res.output
    rep = json.loads(report.read_text())
    assert rep["residual_px"] < 0.25 and rep["rig"]["prism_apex_deg"] == 30.0
    crossed = tmp_path / "crossed.tif"  # the rig puts B right of A: not one above the other
    res = CliRunner().invoke(cli, ["stitch", str(src), "--layout", "2x1", "--rig", str(rig_file),
                                   "-o", str(crossed)])
    assert res.exit_code == 1 and "--layout 2x1 contradicts the rig" in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not crossed.exists()
    bad = tmp_path / "bad.yaml"
    bad.write_text("focal_mm: 6\n")
    out2 = tmp_path / "pano2.tif"
    res = CliRunner().invoke(cli, ["stitch", str(src), "--rig", str(bad), "-o", str(out2)])
    assert res.exit_code == 1 and "no 'views' key" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out2.exists()


@pytest.mark.slow
@pytest.mark.parametrize("model", ["translation", "homography"])
def test_quadpixel_pyramid_full_demo_size(model):
    views, truth, rig = quad(1024)
    pano, rep = stitch(views, layout="2x2", rig=rig, model=model)
    if model == "translation":
        check_rig_panorama(pano, rep, {"x": truth["stitched_field_deg"]["x"]})
    else:  # a homography near the identity: the marker still lands on the axis
        found, _ = red_disc(pano, rep.axis_px)
        assert np.linalg.norm(found - rep.axis_px) < 1.0
        assert rep.residual_px is not None and rep.residual_px < 0.25


def test_rig_panorama_matches_the_analytic_scene():
    """Views of an analytic scene through the quad-pixel pyramid, views 1-3 a fraction of a pixel
    off the rig's prediction: each panorama pixel is one Lanczos resampling of a view: RMS
    7.0e-4 of a 0.15-std scene here (the former undistort-then-place, two resamplings: 8.2e-4,
    which this test refuses; docs/stitch.md)."""
    from plenocli.io.rigfile import read_rig
    from plenocli.synth.rig import random_scene

    rig = read_rig(str(Path(__file__).resolve().parents[1] / "configs" / "rigs"
                       / "quadpixel_pyramid.yaml"))
    scene = random_scene(seed=5, min_period_px=8.0)
    shape = (384, 384)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    offsets = ((0.0, 0.0), (0.37, 0.41), (-0.29, 0.33), (0.45, -0.21))
    views = np.stack([scene(*(c + d for c, d in zip(view_to_common(rig, k, xx, yy, shape), o,
                                                     strict=True)))
                      for k, o in enumerate(offsets)]).astype(np.float32)
    pano, rep = stitch(views, layout="2x2", rig=rig)
    for k, (dx, dy) in enumerate(offsets):
        expected = np.array(rep.canvas_origins_px[k]) - rep.canvas_origins_px[0] + [dy, dx]
        assert np.abs(np.array(rep.shifts_px[k]) - expected).max() < 0.005
    rr, cc = np.mgrid[0:pano.shape[0], 0:pano.shape[1]].astype(np.float64)
    origin, canvas = rep.origin_px, rep.canvas_origins_px[0]
    truth = scene(cc - origin[1] + canvas[1], rr - origin[0] + canvas[0])
    from scipy import ndimage
    inner = ndimage.binary_erosion(np.isfinite(pano), iterations=8)
    rms = float(np.sqrt(np.mean((pano[inner] - truth[inner]) ** 2)))
    print(f"RMS error vs the scene {rms:.2e}")
    assert rms < 8e-4


def test_the_reduced_pass_and_the_measured_blocks_only_narrow_the_work(monkeypatch):
    """Views 768 x 512 are first registered halved (plenocli.stitch.coarse), then at full
    resolution near that shift only, on the most textured rows when the budget is small; the
    overlap is measured on blocks. Shifts stay the full search's within 0.01 px, gains within
    1e-3, the overlap area exact, and the report keeps the rig's own prediction."""
    from plenocli.stitch import coarse, overlaps

    views, _, rig = dual(768)
    assert coarse.reduction(views.shape[-2:]) == 2
    reduced_shapes = []
    search = coarse.estimate_translation
    monkeypatch.setattr(coarse, "estimate_translation",
                        lambda a, b, **kw: reduced_shapes.append(a.shape) or search(a, b, **kw))
    monkeypatch.setattr(coarse, "FINE_PIXELS", 1 << 16)
    monkeypatch.setattr(overlaps, "MEASURE_PIXELS", 1 << 16)
    _, fast = stitch(views, layout="1x2", rig=rig)
    assert reduced_shapes and max(reduced_shapes)[0] < views.shape[-2]  # halved canvases
    monkeypatch.undo()
    monkeypatch.setattr(coarse, "reduction", lambda shape: 1)
    monkeypatch.setattr(overlaps, "MEASURE_PIXELS", 1 << 30)
    _, full = stitch(views, layout="1x2", rig=rig)
    assert np.abs(np.subtract(fast.shifts_px, full.shifts_px)).max() < 0.01
    assert np.allclose(fast.gains, full.gains, rtol=1e-3)
    assert fast.pairs[0]["overlap_px_area"] == full.pairs[0]["overlap_px_area"]
    assert fast.pairs[0]["expected_shift_px"] == full.pairs[0]["expected_shift_px"]
    assert fast.residual_px < 0.25 and full.residual_px < 0.25
