"""plenocli.stitch on synthetic rigs with known geometry, bad inputs, and real texture."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage

from plenocli.stitch import StitchError, estimate_translation, refine_homography, stitch, undistort
from plenocli.synth.rig import make_rig


def apply_matrix(h: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = np.c_[pts, np.ones(len(pts))] @ np.asarray(h).T
    return q[:, :2] / q[:, 2:]


def _corner_error(truth: dict, report) -> float:
    rows, cols = truth["view_shape"]
    corners = np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
    return max(float(np.abs(apply_matrix(t, corners) - apply_matrix(e, corners)).max())
               for t, e in zip(truth["relative"][1:],
                               report.transform["view_to_reference"][1:], strict=True))


@pytest.mark.parametrize("layout", ["1x2", "2x1", "2x2"])
@pytest.mark.parametrize("vignetting,noise", [(0.0, 0.0), (0.2, 0.003)])
def test_translation_recovered_within_0p1_px(layout, vignetting, noise):
    views, _, truth = make_rig(layout=layout, view_shape=(300, 400), overlap=0.3,
                               vignetting=vignetting, noise=noise, seed=3)
    _, report = stitch(views, layout=layout)
    shifts = np.array(report.shifts_px)
    assert np.abs(shifts - np.array(truth["shifts_px"])).max() < 0.1
    assert report.layout == layout


# every layout, noise-free and with noise + 10 % vignetting: corner error within 0.5 px.
# 2x1 views are 500 x 400 so that the overlap (30 % of 500) and the extrapolation to the far
# corners equal the 1x2 case transposed
@pytest.mark.parametrize("layout,seed", [("1x2", 1), ("1x2", 5), ("2x1", 1), ("2x1", 3),
                                         ("2x2", 1)])
@pytest.mark.parametrize("vignetting,noise", [(0.0, 0.0), (0.1, 0.003)])
def test_homography_corner_error_within_0p5_px(layout, seed, vignetting, noise):
    shape = (500, 400) if layout == "2x1" else (400, 500)
    views, _, truth = make_rig(layout=layout, model="homography", view_shape=shape,
                               overlap=0.3, perspective_px=4.0, vignetting=vignetting,
                               noise=noise, seed=seed)
    _, report = stitch(views, layout=layout, model="homography")
    # noise-free views of the analytic scene are related by an exact homography: the
    # photometric fit (cubic B-spline resampling of view b) recovers it within 0.02 px at the
    # far corners over seeds 1-6; noise and vignetting leave up to about 0.06 px
    assert _corner_error(truth, report) < (0.03 if noise == 0 else 0.2)
    assert all(p["inliers"] >= 12 for p in report.pairs)
    assert all(p["refinement"] == "photometric" for p in report.pairs)
    if layout == "2x2":
        assert report.closure_px is not None


def test_refine_homography_recovers_from_a_perturbed_start():
    views, _, truth = make_rig(layout="1x2", model="homography", view_shape=(300, 400),
                               overlap=0.3, perspective_px=4.0, seed=11)
    true_h = np.array(truth["relative"][1])
    start = _translation_matrix_px(0.8, -1.2) @ true_h  # 1.4 px off everywhere
    refined, info = refine_homography(views[0], views[1], start)
    rows, cols = 300, 400
    corners = np.float64([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]])
    assert np.abs(apply_matrix(refined, corners) - apply_matrix(true_h, corners)).max() < 0.01
    assert np.abs(apply_matrix(start, corners) - apply_matrix(true_h, corners)).max() > 1.0
    assert info["photometric_iterations"] >= 2


def test_refine_homography_refuses_a_tiny_overlap():
    views, _, truth = make_rig(layout="1x2", model="homography", view_shape=(100, 120),
                               overlap=0.3, seed=12)
    far = _translation_matrix_px(0.0, 118.0) @ np.array(truth["relative"][1])
    with pytest.raises(ValueError, match="overlap"):
        refine_homography(views[0], views[1], far)


def _translation_matrix_px(dy: float, dx: float) -> np.ndarray:
    m = np.eye(3)
    m[0, 2], m[1, 2] = dx, dy
    return m


def _true_panorama(truth: dict, report, gain0: float) -> np.ndarray:
    """The analytic scene evaluated on the panorama grid (view 0's pixels, offset by
    origin_px)."""
    rows, cols = report.panorama_shape
    oy, ox = report.origin_px
    my, mx = truth["scene_origin"]
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    return gain0 * truth["scene"](xx - ox + mx, yy - oy + my)


@pytest.mark.parametrize("layout,blend", [("1x2", "feather"), ("2x2", "feather"),
                                          ("2x2", "multiband")])
def test_panorama_matches_scene_psnr(layout, blend):
    views, _, truth = make_rig(layout=layout, view_shape=(240, 320), overlap=0.25, seed=5)
    pano, report = stitch(views, layout=layout, blend=blend)
    expected = _true_panorama(truth, report, truth["gains"][0])
    covered = np.isfinite(pano)
    assert covered.mean() > 0.95
    mse = np.mean((pano[covered] - expected[covered]) ** 2)
    psnr = 10 * np.log10(1.0 / mse)  # scene peak is 1
    assert psnr >= 35, psnr
    np.testing.assert_allclose(np.array(report.gains)[:, 0],
                               truth["gains"][0] / np.array(truth["gains"]), rtol=5e-3)


def test_fov_doubling_two_1000px_views_10pct_overlap():
    views, _, truth = make_rig(layout="1x2", view_shape=(200, 1000), overlap=0.1, jitter_px=0.0,
                               seed=2)
    pano, report = stitch(views)
    assert abs(report.shifts_px[1][1] - 900) < 0.1
    assert 1899 <= pano.shape[1] <= 1901
    assert report.pairs[0]["overlap_fraction"] == pytest.approx(0.1, abs=1e-3)


def test_colour_views_stitched_per_channel():
    views, _, truth = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.3, seed=4)
    colour = np.stack([views, 0.5 * views, 0.25 * views], axis=1)  # (V, C, rows, cols)
    pano, report = stitch(colour)
    grey, _ = stitch(views)
    assert pano.shape == (3,) + grey.shape
    np.testing.assert_allclose(pano[1], 0.5 * grey, rtol=1e-3, atol=1e-4)
    assert report.channels == 3


def test_nan_pixels_are_not_data():
    views, _, truth = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.3, seed=6)
    views[1, 50:60, 100:110] = np.nan  # e.g. B where S clipped
    pano, report = stitch(views)
    assert np.abs(np.array(report.shifts_px[1]) - truth["shifts_px"][1]).max() < 0.1
    assert np.isfinite(pano).all() or np.isnan(pano).mean() < 0.02
    # the hole lies outside view 0: only view 1 covers it, so the panorama is NaN there
    y = 55 + report.origin_px[0] + truth["shifts_px"][1][0]
    x = 105 + report.origin_px[1] + truth["shifts_px"][1][1]
    assert x > 260 + report.origin_px[1]
    assert np.isnan(pano[int(round(y)), int(round(x))])


def test_transform_reapplied_to_a_later_capture():
    views, _, truth = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.3, seed=7)
    _, report = stitch(views)
    later = views * 0.7
    pano2, report2 = stitch(later, transform=report.transform)
    assert report2.transform_source == "given"
    assert report2.shifts_px == report.shifts_px
    with pytest.raises(StitchError, match="register them again"):
        stitch(views[:, :100, :200], transform=report.transform)


def test_undistort_inverts_radial_distortion():
    views, _, _ = make_rig(layout="1x2", view_shape=(200, 260), seed=8)
    img = views[0]
    rows, cols = img.shape
    cy, cx = (rows - 1) / 2, (cols - 1) / 2
    k1 = 0.02
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    # distort: distorted(p_d) = img(p_u); sample img at p_u with p_d = p_u (1 + k1 r_u^2)
    norm2 = cy**2 + cx**2
    r_d2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / norm2
    scale = 1 / (1 + k1 * r_d2)  # first-order inverse, refined twice
    for _ in range(3):
        r_u2 = r_d2 * scale**2
        scale = 1 / (1 + k1 * r_u2)
    distorted = ndimage.map_coordinates(img, [cy + (yy - cy) * scale, cx + (xx - cx) * scale],
                                        order=3)
    back = undistort(distorted.astype(np.float32), k1)
    inner = (slice(20, -20), slice(20, -20))
    err_back = np.nanmean(np.abs(back[inner] - img[inner]))
    err_distorted = np.nanmean(np.abs(distorted[inner] - img[inner]))
    assert err_back < 0.2 * err_distorted


# --- bad input ----------------------------------------------------------------------------
def test_views_without_overlap_are_refused():
    views, _, _ = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.0, jitter_px=0,
                           seed=9)
    # overlap 0: view 1 starts exactly where view 0 ends; shift it 40 px further away
    far, _, _ = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.0, seed=10)
    with pytest.raises(StitchError, match="no reliable overlap|no overlap") as refused:
        stitch(np.stack([views[0], far[1]]), layout="1x2")
    # views through prisms can hide their overlap: the refusal says what to pass
    assert "prism" in str(refused.value) and "--rig RIG.yaml" in str(refused.value)


def test_views_without_texture_are_refused():
    flat = np.full((2, 200, 260), 0.5, np.float32)
    with pytest.raises(StitchError, match="no texture"):
        stitch(flat, layout="1x2")
    noise = np.random.default_rng(0).normal(0.5, 0.01, (2, 200, 260)).astype(np.float32)
    with pytest.raises(StitchError, match="no reliable overlap|no overlap"):
        stitch(noise, layout="1x2")
    with pytest.raises(StitchError, match="no texture|too few features|RANSAC|only"):
        stitch(noise, layout="1x2", model="homography")


@pytest.mark.parametrize("views,match", [
    ([np.zeros((100, 120)), np.zeros((100, 130))], "different size"),
    ([np.zeros((3, 100, 120)), np.zeros((100, 120))], "channel count"),
    ([np.zeros((100, 120))] * 3, "2 or 4 views"),
])
def test_mismatched_views_rejected(views, match):
    with pytest.raises(StitchError, match=match):
        stitch(views)


def test_bad_parameters_named():
    views, _, _ = make_rig(layout="1x2", view_shape=(100, 120), seed=1)
    with pytest.raises(ValueError, match="model"):
        stitch(views, model="affine")
    with pytest.raises(ValueError, match="blend"):
        stitch(views, blend="max")
    with pytest.raises(StitchError, match="needs 4 views"):
        stitch(views, layout="2x2")


def test_estimate_translation_direction_checked():
    with pytest.raises(ValueError, match="direction"):
        estimate_translation(np.zeros((50, 50)), np.zeros((50, 50)), direction="d")


# --- real texture ---------------------------------------------------------------------------
def _origami(realdata):
    path = realdata / "raytrix" / "origami" / "frame0.png"
    rgb = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return cv2.cvtColor(rgb, cv2.COLOR_BGR2GRAY).astype(np.float32)


@pytest.mark.realdata
@pytest.mark.parametrize("direction", ["h", "v"])
def test_origami_binned_crops_offset_recovered(realdata, direction):
    grey = _origami(realdata)
    binned = grey.reshape(1024, 2, 1024, 2).mean(axis=(1, 3))
    smooth = cv2.GaussianBlur(binned, (0, 0), 1.5)
    dy, dx = (7, 330) if direction == "h" else (330, -5)
    r0, c0 = 200, 200
    a = smooth[r0:r0 + 420, c0:c0 + 420]
    b = smooth[r0 + dy:r0 + dy + 420, c0 + dx:c0 + dx + 420]
    _, report = stitch(np.stack([a, b]))
    assert report.layout == ("1x2" if direction == "h" else "2x1")
    assert np.abs(np.array(report.shifts_px[1]) - [dy, dx]).max() < 0.5


@pytest.mark.realdata
@pytest.mark.slow
def test_origami_refocused_crops_offset_recovered(realdata):
    from plenocli.io.gridfile import read_grid
    from plenocli.refocus import refocus

    grey = _origami(realdata)
    grid = read_grid(realdata / "raytrix" / "origami" / "calib.xml", image_shape=grey.shape)
    image, _ = refocus(grey, grid, s=0.2, g=4.0, view="full")
    image = np.asarray(image, np.float32)
    rows, cols = image.shape[-2:]
    w = int(cols * 0.6)
    dx = cols - w - 10
    a = image[..., 10:rows - 10, 10:10 + w]
    b = image[..., 10:rows - 10, 10 + dx:10 + dx + w]
    _, report = stitch(np.stack([a, b]), layout="1x2")
    assert np.abs(np.array(report.shifts_px[1]) - [0, dx]).max() < 0.5


def test_a_two_by_two_whose_pairs_do_not_close_is_refused(monkeypatch):
    """Four views reach the last one through two neighbours; one pair matched 12 px off its
    true place must stop the stitch, not make a ghosted panorama."""
    from plenocli.stitch import registration

    true = {(0, 1): (1.0, 100.0), (0, 2): (80.0, -2.0), (1, 3): (79.0, 3.0),
            (2, 3): (0.0, 105.0)}

    def measured(shifts):
        def pair(images, a, b, direction, model, search, prior, tol, shape, found):
            return np.array(shifts[(a, b)], float), {}
        return pair

    luma = np.zeros((4, 120, 160), np.float32)

    def images(a, b, _):
        return luma[a], luma[b], (0, 0), (0, 0)

    expected = {pair: (None, None) for pair in true}
    monkeypatch.setattr(registration, "_measure_pair", measured(true))
    _, _, closure = registration.register(images, 4, (120, 160), "2x2", "translation", {},
                                          expected)
    assert closure < 1e-9
    monkeypatch.setattr(registration, "_measure_pair",
                        measured({**true, (2, 3): (0.0, 117.0)}))
    with pytest.raises(StitchError, match="do not close"):
        registration.register(images, 4, (120, 160), "2x2", "translation", {}, expected)


def test_the_steps_say_what_the_stitch_is_doing():
    import logging

    seen = []

    class Steps(logging.Handler):
        def emit(self, record):
            seen.append(record.getMessage())

    log = logging.getLogger("plenocli")
    handler, level = Steps(), log.level
    log.addHandler(handler)
    log.setLevel(logging.DEBUG)
    try:
        views, _, _ = make_rig(layout="1x2", view_shape=(200, 260), overlap=0.3, seed=7)
        stitch(views, layout="1x2")
    finally:
        log.removeHandler(handler)
        log.setLevel(level)
    assert "registering views 0 and 1" in seen
    assert "measuring the overlap of views 0 and 1" in seen
    assert any(s.startswith("blending band 1 of 1, view 2 of 2") for s in seen)


@pytest.mark.parametrize("iterations", [1, 2, 3])
def test_erode_is_scipy_binary_erosion(iterations):
    from plenocli.stitch.views import erode

    rng = np.random.default_rng(iterations)
    mask = rng.random((97, 131)) > 0.05
    mask[:, :9] = False
    mask[40:60, 50:70] = False
    assert np.array_equal(erode(mask, iterations),
                          ndimage.binary_erosion(mask, iterations=iterations))


def test_overlap_area_from_the_geometry_is_that_of_the_maps():
    """A plain homography's coverage is solved row by row from its geometry, the pixels near a
    run's end mapped: the count equals the whole maps' (feather > 0) for random homographies,
    shifts landing exactly on pixels and on the 1/64-px cover tolerance included."""
    from plenocli.stitch.overlaps import _covered_by_both
    from plenocli.stitch.warp import ViewMap, feather

    rng = np.random.default_rng(3)
    for _ in range(40):
        shape = (int(rng.integers(40, 200)), int(rng.integers(40, 200)))
        maps = []
        for k in range(2):
            h = np.eye(3)
            h[:2, 2] = rng.integers(-20, 20, 2) + rng.choice([0, 0.5, 1 / 64, -1 / 64], 2)
            if k:
                h[:2, :2] += rng.normal(0, 0.05, (2, 2))
                h[2, :2] = rng.normal(0, 3e-4, 2)
            maps.append(ViewMap(shape, h))
        region = (slice(int(rng.integers(0, 20)), shape[0] + 30),
                  slice(int(rng.integers(0, 20)), shape[1] + 30))
        whole = 0
        for (_, xa, ya, _), (_, xb, yb, _) in zip(maps[0].bands(region), maps[1].bands(region),
                                                  strict=True):
            whole += int(np.count_nonzero((feather(xa, ya, shape, None, None) > 0)
                                          & (feather(xb, yb, shape, None, None) > 0)))
        assert _covered_by_both(maps[0], maps[1], region, None, None) == whole


def test_views_of_one_field_are_told_there_is_nothing_to_extend():
    """audit 8 E11: two views of one field 3 px apart (a stereo or dual-pixel pair) were told
    they may not overlap; they overlap almost whole, past the 70 % the search reaches."""
    texture = ndimage.gaussian_filter(np.random.default_rng(4).random((300, 420)), 2.0)
    views = np.stack([texture[:, :400], texture[:, 3:403]]).astype(np.float32)
    with pytest.raises(StitchError, match="show one field"):
        stitch(views)


def test_a_vertical_pair_forced_side_by_side_is_told_its_layout():
    """audit 9 E7: a vertical pair given --layout 1x2 was an "ambiguous overlap (a periodic
    scene?)"; it registers one above the other, so that is what is said."""
    views, _, truth = make_rig(layout="2x1", view_shape=(300, 400), overlap=0.3, seed=5)
    _, report = stitch(views, layout="2x1")
    assert np.abs(np.array(report.shifts_px) - np.array(truth["shifts_px"])).max() < 0.1
    with pytest.raises(StitchError, match=r"show no overlap side by side \(--layout 1x2\) but "
                                          r"register one above the other: give --layout 2x1"):
        stitch(views, layout="1x2")


def test_a_negated_view_or_a_pair_its_names_place_is_not_told_another_layout():
    """audit 13 E1: views named L,R (placed side by side by their names) with R negated were
    told to give --layout 2x1, which the names forbid. A view whose levels are mostly below
    zero where the other's are above is named; a pair the names place that matches only the
    other way is not told to change --layout."""
    views, _, _ = make_rig(layout="2x1", view_shape=(300, 400), overlap=0.3, seed=5)
    with pytest.raises(StitchError, match=r"do not register side by side, where their names "
                                          r"L,R place them .*rule out"):
        stitch(views, layout="1x2", named=["L", "R"])
    flipped = np.stack([views[0], -views[1]])
    for layout in ("1x2", "auto"):
        with pytest.raises(StitchError, match=r"view 1's levels are mostly below zero "
                                              r"\(median -.*check how view 1 was made"):
            stitch(flipped, layout=layout, named=["L", "R"] if layout == "1x2" else None)
    _, report = stitch(views, layout="2x1")  # audit 16 M2: placed by a saved transform
    with pytest.raises(StitchError, match=r"view 1's levels are mostly below zero "
                                          r"\(median -.*check how view 1 was made"):
        stitch(np.stack([views[0], -views[1]]), transform=report.transform)
    dark = np.stack([views[0], views[1]]) - np.float32(np.median(views[1]))  # above black
    with pytest.raises(StitchError) as err:
        stitch(dark, layout="1x2")
    assert "below zero" not in str(err.value)


def test_a_pair_not_found_within_the_users_overlap_is_told_the_overlap_found_without_it():
    """audit 9 E7: a wrong --overlap was "ambiguous overlap (a periodic scene?); give the
    expected overlap (--overlap)"; the search the user restricted is named, and what a search
    without it finds."""
    views, _, truth = make_rig(layout="1x2", view_shape=(300, 400), overlap=0.3, seed=3)
    found = f"{1 - truth['shifts_px'][1][1] / 400:.2f}"  # 1 - the shift over the view's width
    with pytest.raises(StitchError, match=rf"no overlap within --overlap 0.7 \+- 0.1 of the view; "
                                          rf"searched without it they overlap by {found} side by "
                                          rf"side: give --overlap {found}, or leave it out"):
        stitch(views, overlap=0.7, overlap_tolerance=0.1)


def test_an_ambiguous_match_within_the_given_overlap_does_not_ask_for_an_overlap():
    """audit 11 E1: a periodic scene searched within --overlap was told to "give the expected
    overlap (--overlap)"; it was given: the advice is to narrow its tolerance."""
    tile = ndimage.gaussian_filter(np.random.default_rng(7).random((300, 24)), 1.5)
    scene = np.tile(tile, (1, 30))  # repeats every 24 px across
    views = np.stack([scene[:, :400], scene[:, 280:680]]).astype(np.float32)
    with pytest.raises(StitchError, match="ambiguous") as refused:
        stitch(views, layout="1x2", overlap=0.3, overlap_tolerance=0.1)
    assert "give the expected overlap" not in str(refused.value)
    assert "narrow --overlap-tolerance" in str(refused.value)


@pytest.mark.parametrize("offset", [1.1, 1.5, 4.0])  # times the views' median
def test_gains_are_not_measured_on_overlaps_below_zero(offset):
    # audit 12 W4: views with an offset left in gave gains of 1 without a word where an
    # overlap's mean was below 0, exit 0
    views, _, _ = make_rig(layout="2x2", view_shape=(200, 260), overlap=0.3, seed=12)
    _, plain = stitch(views, layout="2x2")
    assert plain.gains[1][0] == pytest.approx(1 / 0.85, rel=0.02)
    shifted = views - np.float32(offset * float(np.median(views)))
    with pytest.raises(StitchError, match="no exposure gain can be measured.*--gains none"):
        stitch(shifted, layout="2x2")
    _, kept = stitch(shifted, layout="2x2", match_gain=False)
    assert kept.gains == [[1.0]] * 4
    assert np.allclose(kept.shifts_px, plain.shifts_px, atol=0.01)


def test_gains_of_a_dark_noisy_scene_above_black_are_measured():
    """review 12: a dark, bias-subtracted scene, its noise about a black of 0 below zero in a
    third of its pixels, was refused as "near or below zero"; its gains are those of the
    noise-free views (the overlap means are unbiased), within 1 %."""
    views, _, _ = make_rig(layout="2x2", view_shape=(200, 260), overlap=0.3, seed=12)
    dark = (views / np.float32(views.max())) ** 6
    noise = np.random.default_rng(3).normal(0.0, 0.5 * float(dark.mean()), dark.shape)
    noisy = (dark + noise).astype(np.float32)
    assert (noisy < 0).mean() > 0.2
    _, clean = stitch(dark, layout="2x2")
    _, measured = stitch(noisy, layout="2x2")
    np.testing.assert_allclose(measured.gains, clean.gains, rtol=0.01)
