"""Refocus by Lanczos splatting (paper Eq. 3): reference implementation, flux, constants,
synthetic planes with known depth and disparity."""

from __future__ import annotations

import numpy as np
import pytest

from plenocli.model.lensgrid import LensGrid
from plenocli.refocus import (
    KERNELS,
    VIEWS,
    kernel_table,
    output_shape,
    parse_g,
    refocus,
    sharpness,
    splat_sums,
    unjudged,
)
from plenocli.synth.focused import raytrix_scene, texture_at

GRID = LensGrid(pitch_px=20.2, angle_rad=0.1, offset_xy=(7.3, 11.9))


def reference_sums(frame, grid, *, s, g, view, mask_width, kernel, radius=None, cfa=None):
    """Plain numpy Eq. 3 splatting, pixel by pixel: the compiled kernel must agree."""
    rows, cols = frame.shape
    a = KERNELS[kernel]
    table = kernel_table(a)
    bins = table.shape[0] - 1
    y, x = np.mgrid[0:rows, 0:cols].astype(float)
    i, j = grid.nearest_index(x, y)
    c = grid.lattice_xy(i, j)
    if grid.centres_xy is not None:
        lookup = {(int(p), int(q)): xy for (p, q), xy in zip(grid.indices, grid.centres_xy,
                                                             strict=True)}
        for r in range(rows):
            for cc in range(cols):
                key = (int(i[r, cc]), int(j[r, cc]))
                if key in lookup:
                    c[r, cc] = lookup[key]
    dx, dy = x - c[..., 0], y - c[..., 1]
    xs, ys = VIEWS[view]
    keep = np.ones(frame.shape, bool)
    half = mask_width / 2
    keep &= (dx < -half) if xs < 0 else (dx > half) if xs > 0 else True
    keep &= (dy < -half) if ys < 0 else (dy > half) if ys > 0 else True
    if radius is not None:
        keep &= dx ** 2 + dy ** 2 <= radius ** 2
    X = s * (g * dx + c[..., 0])
    Y = s * (g * dy + c[..., 1])
    shape = output_shape(frame.shape, s)
    n_chan = 3 if cfa else 1
    sums = np.zeros((n_chan,) + shape)
    weights = np.zeros((n_chan,) + shape)
    ntap = table.shape[1]
    for r, cc in zip(*np.nonzero(keep), strict=True):
        ch = "RGB".index(cfa[(r % 2) * 2 + cc % 2]) if cfa else 0
        bx, by = np.floor(X[r, cc]), np.floor(Y[r, cc])
        wx = table[int((X[r, cc] - bx) * bins + 0.5)]
        wy = table[int((Y[r, cc] - by) * bins + 0.5)]
        for ky in range(ntap):
            orow = int(by) - ntap // 2 + 1 + ky
            for kx in range(ntap):
                ocol = int(bx) - ntap // 2 + 1 + kx
                if 0 <= orow < shape[0] and 0 <= ocol < shape[1]:
                    sums[ch, orow, ocol] += wy[ky] * wx[kx] * frame[r, cc]
                    weights[ch, orow, ocol] += wy[ky] * wx[kx]
    return sums, weights


@pytest.mark.parametrize("view,kernel,g,cfa,radius", [
    ("full", "lanczos3", 4.0, None, None),
    ("left", "lanczos2", 3.0, None, None),
    ("q10", "lanczos4", 2.5, None, None),
    ("bottom", "bilinear", 4.0, "GRBG", None),
    ("full", "lanczos3", 1.0, None, 6.0),
])
def test_compiled_kernel_matches_reference(view, kernel, g, cfa, radius):
    rng = np.random.default_rng(3)
    frame = rng.random((46, 58)).astype(np.float32)
    kw = dict(s=0.3, g=g, view=view, mask_width=2.0, kernel=kernel, radius=radius, cfa=cfa)
    sums, weights = splat_sums(frame, GRID, **kw)
    ref_sums, ref_weights = reference_sums(frame.astype(float), GRID, **kw)
    np.testing.assert_allclose(weights, ref_weights, atol=1e-9)
    np.testing.assert_allclose(sums, ref_sums, atol=1e-9)


def test_refined_centres_replace_lattice_centres():
    rng = np.random.default_rng(4)
    frame = rng.random((50, 60)).astype(np.float32)
    base = LensGrid(pitch_px=12.0, angle_rad=0.0, offset_xy=(5.0, 6.0), image_shape=(50, 60))
    idx, xy = base.lens_centres()
    moved = xy + rng.uniform(-0.8, 0.8, xy.shape)
    keep = np.arange(len(idx)) % 3 != 0  # some lenses without a refined centre: lattice used
    grid = LensGrid(pitch_px=12.0, angle_rad=0.0, offset_xy=(5.0, 6.0),
                    centres_xy=moved[keep], indices=idx[keep])
    kw = dict(s=0.25, g=3.0, view="right", mask_width=1.0, kernel="lanczos3")
    sums, weights = splat_sums(frame, grid, **kw)
    ref = reference_sums(frame.astype(float), grid, **kw)
    np.testing.assert_allclose(weights, ref[1], atol=1e-9)
    np.testing.assert_allclose(sums, ref[0], atol=1e-9)
    plain = splat_sums(frame, base, **kw)
    assert not np.allclose(plain[0], sums)  # the refined centres really were used


@pytest.mark.parametrize("kernel", list(KERNELS))
@pytest.mark.parametrize("view", ["full", "left", "q01"])
def test_splatting_conserves_flux(kernel, view):
    rng = np.random.default_rng(5)
    frame = np.zeros((300, 400), np.float32)
    frame[80:220, 90:310] = rng.random((140, 220))  # far from the borders: no tap falls off
    image, weight = refocus(frame, GRID, s=0.2, g=4.0, view=view, kernel=kernel, min_weight=0)
    sums, weights = splat_sums(frame, GRID, s=0.2, g=4.0, view=view, kernel=kernel)
    y, x = np.mgrid[0:300, 0:400].astype(float)
    i, j = GRID.nearest_index(x, y)
    d = np.stack([x, y], -1) - GRID.lattice_xy(i, j)
    kept = {"full": np.ones(frame.shape, bool), "left": d[..., 0] < -1,
            "q01": (d[..., 0] > 1) & (d[..., 1] < -1)}[view]
    expected = float(frame[kept].astype(float).sum())
    assert sums.sum() == pytest.approx(expected, rel=1e-9)
    ok = np.isfinite(image)
    assert float((image[ok].astype(float) * weight[ok]).sum()) == pytest.approx(expected, rel=1e-5)


@pytest.mark.parametrize("view", list(VIEWS))
@pytest.mark.parametrize("cfa", [None, "RGGB"])
def test_constant_image_refocuses_to_the_constant(view, cfa):
    frame = np.full((240, 320), 37.5, np.float32)
    image, weight = refocus(frame, GRID, s=0.2, g=4.0, view=view, cfa=cfa)
    assert image.shape == ((3,) if cfa else ()) + output_shape(frame.shape, 0.2)
    ok = np.isfinite(image)
    assert ok.mean() > 0.9
    np.testing.assert_allclose(image[ok], 37.5, rtol=1e-3)
    assert np.all(weight[ok] > 0)


def test_uncovered_pixels_are_nan_not_noise():
    frame = np.full((200, 200), 1.0, np.float32)
    image, weight = refocus(frame, GRID, s=0.2, g=1.0, radius=3.0)  # sparse disks, gaps between
    assert np.isnan(image).any()
    typical = np.median(weight[weight > 0])
    assert np.all(np.isnan(image[weight < 0.25 * typical]))
    np.testing.assert_allclose(image[np.isfinite(image)], 1.0, rtol=1e-5)


def psnr_covered(image, truth, margin=8):
    ok = np.isfinite(image)
    ok[:margin] = ok[-margin:] = False
    ok[:, :margin] = ok[:, -margin:] = False
    peak = float(truth.max() - truth.min())
    return 10 * np.log10(peak ** 2 / np.mean((image[ok] - truth[ok]) ** 2))


@pytest.mark.parametrize("kernel", ["lanczos2", "lanczos3", "lanczos4", "bilinear"])
def test_plane_refocused_at_its_true_g_matches_the_texture(kernel):
    sensor, grid, truth, info = raytrix_scene(seed=11, max_freq=0.2)
    g_true = info["g_true"]
    image, _ = refocus(sensor, grid, s=info["s"], g=g_true, kernel=kernel)
    assert psnr_covered(image, truth) >= 30.0
    period = info["s"] * info["pitch_px"]
    at_true = sharpness(image, lens_period_px=period)
    for wrong in (g_true - 1.0, g_true + 1.0, 1.0):
        other, _ = refocus(sensor, grid, s=info["s"], g=wrong, kernel=kernel)
        assert psnr_covered(other, truth) < psnr_covered(image, truth) - 6
        assert sharpness(other, lens_period_px=period) < at_true


def test_bayer_plane_each_colour_matches_its_texture():
    sensor, grid, truth, info = raytrix_scene(seed=12, cfa="GBRG", max_freq=0.15)
    image, weight = refocus(sensor, grid, s=info["s"], g=info["g_true"], cfa="GBRG")
    assert image.shape[0] == 3
    for ch in range(3):
        assert psnr_covered(image[ch], truth[ch]) >= 30.0
    # R and B have a quarter of the pixels, G half: the weight maps say so
    np.testing.assert_allclose(np.median(weight, axis=(1, 2)) / np.median(weight[1]),
                               [0.5, 1.0, 0.5], rtol=0.05)


def best_shift(image, texture, info, channel=0):
    """Shift d (px, along x) that best explains image(X) = T(X + d): least squares on a grid."""
    rows, cols = image.shape
    Y, X = np.mgrid[0:rows, 0:cols].astype(float)
    ok = np.isfinite(image)
    ok[:10] = ok[-10:] = False
    ok[:, :10] = ok[:, -10:] = False
    box = abs(info["s"] * info["g_true"])
    shifts = np.arange(-3.0, 3.0001, 0.02)
    errs = [np.mean((image[ok] - texture_at(texture, X[ok] + d, Y[ok], box=box,
                                            channel=channel)) ** 2) for d in shifts]
    k = int(np.argmin(errs))
    if 0 < k < len(shifts) - 1:  # parabola through the minimum
        e0, e1, e2 = errs[k - 1], errs[k], errs[k + 1]
        return shifts[k] + 0.02 * 0.5 * (e0 - e2) / (e0 - 2 * e1 + e2)
    return shifts[k]


@pytest.mark.parametrize("dg", [-1.0, 1.0])
def test_left_right_views_off_focus_have_the_expected_disparity(dg):
    sensor, grid, truth, info = raytrix_scene(seed=13, max_freq=0.1)
    texture = {k: np.asarray(v) for k, v in info["texture"].items()}
    s, g_true, g = info["s"], info["g_true"], info["g_true"] + dg
    y, x = np.mgrid[0:sensor.shape[0], 0:sensor.shape[1]].astype(float)
    i, j = grid.nearest_index(x, y)
    dx = x - grid.lattice_xy(i, j)[..., 0]
    shifts = {}
    for view, kept in (("left", dx < -1.0), ("right", dx > 1.0)):
        image, _ = refocus(sensor, grid, s=s, g=g, view=view, mask_width=2.0)
        expected = s * (g_true - g) * dx[kept].mean()  # image(X) = T(X + expected)
        shifts[view] = best_shift(image, texture, info)
        assert shifts[view] == pytest.approx(expected, abs=0.12)
    disparity = shifts["left"] - shifts["right"]
    assert np.sign(disparity) == np.sign(dg)  # left sees T further right when g > g_true
    assert abs(disparity) > 1.5


def test_results_do_not_depend_on_the_band_split():
    rng = np.random.default_rng(6)
    frame = rng.random((600, 300)).astype(np.float32)
    one = splat_sums(frame, GRID, bands=1)
    many = splat_sums(frame, GRID, bands=5)
    np.testing.assert_allclose(many[0], one[0], rtol=1e-12, atol=1e-9)
    again = splat_sums(frame, GRID, bands=5)
    assert np.array_equal(again[0], many[0])


@pytest.mark.parametrize("kwargs,match", [
    (dict(s=0.0), "s must be"), (dict(s=-0.2), "s must be"), (dict(view="up"), "view"),
    (dict(kernel="cubic"), "kernel"), (dict(mask_width=-1), "mask_width"),
    (dict(radius=0.0), "radius"), (dict(cfa="RGBB"), "cfa"), (dict(g=np.inf), "g must"),
])
def test_bad_parameters_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        refocus(np.zeros((40, 40), np.float32), GRID, **kwargs)


@pytest.mark.parametrize("text,expected", [
    ("4", [4.0]), ("2,3,4", [2.0, 3.0, 4.0]), ("2:6:0.5", [2 + 0.5 * k for k in range(9)]),
    ("2:3:0.4", [2.0, 2.4, 2.8]), (3.5, [3.5]),
])
def test_parse_g(text, expected):
    assert parse_g(text) == pytest.approx(expected)


@pytest.mark.parametrize("text", ["a", "6:2:1", "2:6:0", "2:6", ""])
def test_parse_g_refuses(text):
    with pytest.raises(ValueError, match="g must"):
        parse_g(text)


def test_sharpness_ignores_the_lens_pattern_and_prefers_detail():
    rng = np.random.default_rng(7)
    from scipy import ndimage

    detail = ndimage.gaussian_filter(rng.random((200, 200)), 2.0)
    blurred = ndimage.gaussian_filter(detail, 2.0)
    yy, xx = np.mgrid[0:200, 0:200]
    lens = 0.2 * np.cos(2 * np.pi * xx / 4.04)  # lens-grid pattern of period s * pitch
    period = 4.04
    assert sharpness(detail, lens_period_px=period) > sharpness(blurred, lens_period_px=period)
    assert (sharpness(blurred + lens * blurred.std(), lens_period_px=period)
            < sharpness(detail, lens_period_px=period))
    assert sharpness(blurred + lens) > sharpness(blurred)  # an unsmoothed Laplacian is fooled


def test_planes_at_g_beyond_the_pitch_are_not_judged():
    """A channel's samples s |g| step apart reach the lens period s * pitch at |g| = pitch /
    step (step 2 for a Bayer colour): the score has nothing of the plane to judge there."""
    assert unjudged(20.1, 20.2) is None and unjudged(-20.1, 20.2) is None
    assert "lens pitch 20.2 px" in unjudged(20.2, 20.2) and unjudged(-44, 20.2)
    assert unjudged(10.0, 20.2, mosaic=True) is None
    assert "10.1, the lens pitch over the 2 px step" in unjudged(10.1, 20.2, mosaic=True)


def test_sharpness_smooths_each_channel_on_its_own_cover():
    rng = np.random.default_rng(3)
    image = np.repeat(rng.random((1, 60, 80)), 3, axis=0)
    image[0, ::2], image[2, :, ::2] = np.nan, np.nan  # R, B holed on alternate rows / columns
    assert np.isfinite(sharpness(image, lens_period_px=4.04))
    assert np.isnan(sharpness(np.full((60, 80), np.nan), lens_period_px=4.04))


@pytest.mark.parametrize("text,words", [
    ("0", "non-zero numbers of one sign"), ("2,-3", "of one sign"), ("nan", "finite"),
    ("0:1e9:1", "1000000001 refocus planes"), ("1:1001:1", "at most 1000"),
    ("inf:5:1", "start:stop:step"),
])
def test_parse_g_refuses_values_and_sweeps_up_front(text, words):
    with pytest.raises(ValueError, match=words):
        parse_g(text)


def test_parse_g_takes_a_galilean_cameras_negative_g():
    assert parse_g("-4") == [-4.0] and parse_g("-5:-3:1") == [-5.0, -4.0, -3.0]


def test_parse_g_keeps_a_sweep_of_1000():
    assert len(parse_g("1:1000:1")) == 1000


def test_absurd_output_size_is_refused_before_allocating():
    with pytest.raises(ValueError, match="s = 1000"):
        refocus(np.zeros((120, 160), np.float32), GRID, s=1000.0)
    with pytest.raises(ValueError, match="g must be a finite non-zero"):
        refocus(np.zeros((12, 16), np.float32), GRID, g=0.0)


def test_a_sweep_too_large_for_memory_is_refused_up_front():
    from plenocli.refocus import MAX_STACK_PIXELS, check_output_size

    rows_out, cols_out = output_shape((4480, 6720), 1.0)
    pages = MAX_STACK_PIXELS // (rows_out * cols_out) + 1
    check_output_size((4480, 6720), 1.0, pages=pages - 1)
    with pytest.raises(ValueError, match=f"{pages} pages"):
        check_output_size((4480, 6720), 1.0, pages=pages)
