"""Synthetic captures of the prism designs: decode them and check them against their truth."""

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import least_squares

from plenocli.io.raw import decode
from plenocli.pipeline.stages.simulate import simulate
from plenocli.sai import demultiplex
from plenocli.synth import KIND_NAMES, kinds
from plenocli.synth.prismcam import Camera, _chart_hits, render_quadpixel


def quad_views(out_dir, **options):
    truth = simulate("quadpixel-pyramid", out_dir, **options)
    frames, meta = decode(out_dir / truth["files"]["capture"])
    assert meta["views"] == ["R", "G", "B"] and frames.dtype == np.uint16
    views = np.stack([demultiplex(f, 2) for f in frames], axis=-1)  # (4, rows, cols, 3)
    return views, truth, json.loads((out_dir / "truth.json").read_text())


def test_no_prisms_gives_four_identical_views(tmp_path):
    views, truth, on_disk = quad_views(tmp_path, pixels=128, no_prisms=True, seed=4)
    assert on_disk == json.loads(json.dumps(truth))
    assert views.shape == (4, 64, 64, 3)
    assert views.std() > 1000  # a chart, not a blank
    for k in range(1, 4):
        assert np.array_equal(views[k], views[0])
    assert truth["stitched_field_deg"]["x"] == pytest.approx(truth["main_lens_field_deg"],
                                                             rel=0.01)


def test_pyramid_doubles_the_field(tmp_path):
    views, truth, _ = quad_views(tmp_path, pixels=128, seed=4)
    assert not np.array_equal(views[0], views[3])
    main = truth["main_lens_field_deg"]
    assert main == pytest.approx(2 * np.degrees(np.arctan(1.8 / 6.16)))  # 32.6 deg
    for axis in ("x", "y"):  # paper: 32 deg -> 64 deg
        assert truth["stitched_field_deg"][axis] == pytest.approx(2 * main, rel=0.05)
    # Views tile the field: SAI (0, 0) looks to +x +y (chart coordinates), (1, 1) to -x -y.
    centres = {tuple(v["sai"]): v["centre_deg"] for v in truth["views"]}
    assert centres[(0, 0)][0] > 10 and centres[(0, 0)][1] > 10
    assert centres[(1, 1)][0] < -10 and centres[(1, 1)][1] < -10
    assert centres[(0, 1)][0] < -10 and centres[(0, 1)][1] > 10


def red_disc_centre(view, near_xy, window=12):
    """Centroid (x, y) of the saturated-red pixels within ``window`` pixels of ``near_xy``
    (red letters elsewhere on the chart are not the axis marker)."""
    r, g, b = (view[..., k].astype(float) for k in range(3))
    mask = (r > 0.8 * r.max()) & (g < 0.3 * r.max()) & (b < 0.3 * r.max())
    yy, xx = np.mgrid[0:view.shape[0], 0:view.shape[1]] + 0.5
    mask &= (np.abs(xx - near_xy[0]) < window) & (np.abs(yy - near_xy[1]) < window)
    return np.array([xx[mask].mean(), yy[mask].mean()]), mask.sum()


@pytest.mark.parametrize("sai, region", [((0, 0), (1, 1)), ((1, 0), (1, -1))])
def test_rendered_content_matches_the_ray_geometry(tmp_path, sai, region):
    """The chart's axis marker (red disc at chart (0, 0)) appears in each view where the traced
    geometry puts it: solve for the sensor point whose ray through the pupil quarter and its
    prism hits the chart centre, and compare with the disc found in the pixels."""
    pixels = 256
    views, truth, _ = quad_views(tmp_path, pixels=pixels, seed=2)
    view = views[sai[0] * 2 + sai[1]]
    cam = Camera()
    c = 4 * cam.aperture_mm / 2 / (3 * np.pi)
    pupil = np.array([[region[0] * c, region[1] * c]])

    def residual(s):
        return _chart_hits(cam, s.reshape(1, 2), pupil, region)[0]

    s = least_squares(residual, np.zeros(2)).x
    cell = cam.sensor_mm / (pixels // 2)
    expected = s / cell + (pixels // 2) / 2  # view pixel coordinates (x, y)
    found, area = red_disc_centre(view, expected)
    assert area > 10  # the disc (radius ~3.4 view pixels), not a stray pixel
    assert np.allclose(found, expected, atol=1.0)
    # And not where a prism-free view would put it (the centre of the view).
    assert np.linalg.norm(expected - (pixels // 2) / 2) > 20


def test_masked_quarter_with_known_crosstalk(tmp_path):
    views, truth, _ = quad_views(tmp_path, pixels=64, scene="white", open_quarters="00",
                                 crosstalk=0.13)
    flux = views.astype(float).sum(axis=(1, 2, 3))
    assert flux.argmax() == 0
    assert flux[1:].max() / flux[0] == pytest.approx(0.13, rel=1e-3)
    assert [v["open"] for v in truth["views"]] == [True, False, False, False]


def test_same_seed_same_capture_other_seed_other_chart():
    a, _ = render_quadpixel(pixels=64, seed=1)
    b, _ = render_quadpixel(pixels=64, seed=1)
    c, _ = render_quadpixel(pixels=64, seed=2)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_more_rays_average_towards_the_single_ray_render():
    one, _ = render_quadpixel(pixels=64, rays=1, prisms=False, seed=3)
    many, _ = render_quadpixel(pixels=64, rays=8, prisms=False, seed=3)
    assert np.abs(many - one).mean() < 0.1  # same picture, only antialiased
    assert not np.array_equal(many, one)


def test_dualpixel_prism_frames_like_a_dpraw(tmp_path):
    truth = simulate("dualpixel-prism", tmp_path, pixels=192, seed=5, noise_dn=0.0)
    frames, meta = decode(tmp_path / "capture.dng")
    assert meta["views"] == ["S", "A"] and meta["cfa"] == "RGGB"
    assert meta["active_area"] == truth["active_area"]
    top, left, bottom, right = meta["active_area"]
    s = frames[0, top:bottom, left:right].astype(float) - truth["black_level"]
    a = frames[1, top:bottom, left:right].astype(float) - truth["black_level"]
    b = s - a
    assert np.all(frames[:, :, :left] == truth["black_level"])  # optical black
    # Where A and B overlap (B's left edge), the same chart patch is in A `overlap_shift_px`
    # further right: find B's left-edge patch in A (green pixels, half resolution).
    import cv2

    ga, gb = a[0::2, 1::2].astype(np.float32), b[0::2, 1::2].astype(np.float32)
    rows = ga.shape[0]
    patch = gb[rows // 2 - 12: rows // 2 + 12, 0:16]
    score = cv2.matchTemplate(ga, patch, cv2.TM_CCOEFF_NORMED)
    y, x = np.unravel_index(np.argmax(score), score.shape)
    assert score.max() > 0.9
    assert 2 * x == pytest.approx(truth["overlap_shift_px"], abs=3.0)
    assert 2 * y == pytest.approx(2 * (rows // 2 - 12), abs=3.0)
    assert truth["stitched_field_x_deg"] == pytest.approx(2 * 32.58, rel=0.05)


def test_dualpixel_masked_half_gives_the_crosstalk(tmp_path):
    truth = simulate("dualpixel-prism", tmp_path, pixels=96, scene="white", open_halves="A",
                     crosstalk=0.5, noise_dn=0.0)
    frames, _ = decode(tmp_path / "capture.dng")
    top, left, bottom, right = truth["active_area"]
    s = frames[0, top:bottom, left:right].astype(float) - truth["black_level"]
    a = frames[1, top:bottom, left:right].astype(float) - truth["black_level"]
    assert (s - a).sum() / a.sum() == pytest.approx(0.5, rel=0.01)  # the paper's Canon: ~50 %


def test_raytrix_white_micro_images_centre_on_the_truth_lattice(tmp_path):
    truth = simulate("raytrix-prism", tmp_path, pixels=202, scene="white", seed=7)
    frames, meta = decode(tmp_path / "capture.tif")
    img = frames[0].astype(float)
    lat = truth["lattice"]
    assert lat["diameter"] == pytest.approx(20.2)
    rows, cols = img.shape
    # RayCalibData convention: x = W/2 + offset.x, y = H/2 - offset.y for lens (0, 0).
    x0, y0 = cols / 2 + lat["offset"]["x"], rows / 2 - lat["offset"]["y"]
    centres = np.array(lat["centres_xy_px"])
    ij = np.array(lat["indices_ij"])
    assert np.allclose(centres[np.all(ij == 0, axis=1)][0], [x0, y0])
    yy, xx = np.mgrid[0:rows, 0:cols] + 0.5
    checked = 0
    for cx, cy in centres:
        if 15 < cx < cols - 15 and 15 < cy < rows - 15:
            m = (xx - cx) ** 2 + (yy - cy) ** 2 < 10.1 ** 2  # the whole micro-image
            w = img[m]
            assert np.sum(xx[m] * w) / w.sum() == pytest.approx(cx, abs=0.05)
            assert np.sum(yy[m] * w) / w.sum() == pytest.approx(cy, abs=0.05)
            checked += 1
    assert checked > 20


def test_raytrix_prism_left_and_right_pixels_see_different_fields():
    from plenocli.synth.prismcam import render_raytrix

    with_prism, truth = render_raytrix(pixels=202, seed=1, prism=True)
    without, _ = render_raytrix(pixels=202, seed=1, prism=False)
    centres = np.array(truth["lattice"]["centres_xy_px"])
    rows, cols = with_prism.shape
    yy, xx = np.mgrid[0:rows, 0:cols] + 0.5
    from scipy.spatial import cKDTree

    _, near = cKDTree(centres).query(np.stack([xx.ravel(), yy.ravel()], 1))
    dx = (xx.ravel() - centres[near, 0]).reshape(rows, cols)
    left, right = dx < -1, dx > 1
    assert np.array_equal(with_prism[right], without[right])  # the -x pupil half: no prism
    assert not np.array_equal(with_prism[left], without[left])
    assert truth["prism_centre_shift_px"] != 0


@pytest.mark.parametrize("bad, match", [(dict(pixels=15), "pixels"), (dict(rays=0), "rays"),
                                        (dict(crosstalk=1.0), "crosstalk"),
                                        (dict(scene="moon"), "scene")])
def test_bad_options(bad, match):
    with pytest.raises(ValueError, match=match):
        render_quadpixel(**{"pixels": 64, **bad})


def test_kinds_are_registered_and_loaded_one_module_at_a_time():
    assert {"quadpixel-pyramid", "dualpixel-prism", "raytrix-prism", "quadpixel-white",
            "quadpixel-masked", "dualpixel-masked", "dualpixel-white",
            "raytrix-white"} <= set(KIND_NAMES)
    assert kinds()["quadpixel-white"].keywords == {"scene": "white", "no_prisms": True}
    code = ("import sys\nfrom plenocli.synth import generator\n"
            "generator('quadpixel-pyramid')\n"
            "print(sorted(m for m in sys.modules if m.startswith(('plenocli.synth.', 'numba'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert eval(out) == ["plenocli.synth.capture", "plenocli.synth.chart",
                         "plenocli.synth.prismcam", "plenocli.synth.prismsets"]


@pytest.mark.parametrize("kind, apex", [("quadpixel-pyramid", 24.0), ("quadpixel-pyramid", 50.0),
                                        ("dualpixel-prism", 40.0)])
def test_a_prism_that_reflects_a_view_edges_light_is_refused(kind, apex, tmp_path):
    """Audit 10 W4: a capture whose prisms reflect every ray was written black (apex 50: every
    pixel 0, the truth's fields null), exit 0. A view whose corners, edge midpoints or centre
    receive no light is refused, as `optics` refuses the prism."""
    from plenocli.errors import OptionError

    with pytest.raises(OptionError, match="reflects totally"):
        simulate(kind, tmp_path / "s", prism_apex_deg=apex)
    assert not (tmp_path / "s").exists()


def test_the_largest_apex_that_images_every_view_is_taken(tmp_path):
    truth = simulate("quadpixel-pyramid", tmp_path / "s", prism_apex_deg=20.0)
    assert all(np.isfinite(v["field_x_deg"]).all() for v in truth["views"])


def test_memory_does_not_grow_with_the_rays_per_pixel():
    # own-10 (round 10): every view block held all its pupil samples at once, (rays, rows,
    # cols, 2) float64: 1.66 GB at --pixels 64 --rays 100000, growing with --rays
    import tracemalloc

    def peak(rays):
        tracemalloc.start()
        render_quadpixel(pixels=32, rays=rays, prisms=False, seed=3)
        top = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return top

    few, many = peak(2), peak(1500)   # all 1500 samples of a view: 1500 x 16 x 16 x 16 B = 6 MB
    assert many < few + 2_000_000, (few, many)
