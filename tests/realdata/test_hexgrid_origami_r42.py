"""Real Raytrix frames: a scene image calibrates; an independent symmetry check places our grid."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from plenocli import hexgrid
from plenocli.io import raytrix

pytestmark = pytest.mark.realdata


def _load(path):
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)[..., :3].astype(np.float32).sum(-1)


def test_origami_scene_against_xml_and_symmetry(realdata):
    folder = realdata / "raytrix" / "origami"
    image = _load(folder / "frame0.png")
    grid, _ = hexgrid.calibrate(image)
    xml = raytrix.grid_from_calib(raytrix.read_calib(folder / "calib.xml"), image.shape)
    cmp = hexgrid.compare_grids(grid, xml, image.shape)
    assert abs(cmp["pitch_diff_px"]) <= 0.03
    assert abs(cmp["angle_diff_deg"]) <= 0.01
    assert cmp["max_px"] <= 2.0
    # independent check: mean micro-image of each 3 x 3 region, its point-symmetry centre
    _, ours = grid.lens_centres()
    rows, cols = image.shape
    half = int(grid.pitch_px // 2)
    flat = hexgrid.flatten(image, scale_px=grid.pitch_px)
    worse = 0
    for r in range(3):
        for c in range(3):
            sel = ((ours[:, 1] // (rows / 3) == r) & (ours[:, 0] // (cols / 3) == c))
            mean = hexgrid.mean_micro_image(flat, ours[sel], half=half)
            dx, dy = hexgrid.symmetry_centre(mean, radius=0.45 * grid.pitch_px)
            assert np.hypot(dx, dy) <= 0.2, (r, c, dx, dy)
            i, j = xml.nearest_index(ours[sel, 0], ours[sel, 1])
            theirs = xml.lattice_xy(i, j)
            xdx, xdy = hexgrid.symmetry_centre(
                hexgrid.mean_micro_image(flat, theirs, half=half), radius=0.45 * grid.pitch_px)
            worse += np.hypot(xdx, xdy) > np.hypot(dx, dy)
    assert worse >= 7   # the camera's grid is further from the symmetry centres than ours


def _border_contrast(grad: np.ndarray, pitch_px: float, angle_deg: float, nb: int = 32) -> float:
    """How sharply the micro-image borders stand out when every pixel's gradient magnitude is
    folded onto one lattice cell (nb x nb bins of the fractional lattice coordinates): the
    variance of the folded mean after removing its smooth part. Scene content shifts from lens
    to lens (parallax) and blurs out in the fold; the borders (discontinuities) add up only on
    the true lattice. The smooth part is removed because a scene periodicity folds into broad
    stripes (high raw variance, no sharp lines)."""
    from scipy import ndimage

    rows, cols = grad.shape
    yy, xx = np.mgrid[0:rows, 0:cols]
    a, step = np.radians(angle_deg), np.pi / 3
    basis = pitch_px * np.array([[np.cos(a), np.sin(a)], [np.cos(a + step), np.sin(a + step)]])
    inv = np.linalg.inv(basis.T)
    u = inv[0, 0] * xx + inv[0, 1] * yy
    v = inv[1, 0] * xx + inv[1, 1] * yy
    k = (((u % 1) * nb).astype(np.int64) % nb) * nb + ((v % 1) * nb).astype(np.int64) % nb
    total = np.bincount(k.ravel(), grad.ravel().astype(np.float64), nb * nb)
    count = np.bincount(k.ravel(), None, nb * nb)
    mean = (total / np.maximum(count, 1)).reshape(nb, nb)
    filled = (count > 0).reshape(nb, nb).astype(float)   # rational pitch/row ratios skip bins
    near = ndimage.gaussian_filter(mean * filled, 1, mode="wrap") / np.maximum(
        ndimage.gaussian_filter(filled, 1, mode="wrap"), 1e-9)
    mean = np.where(filled > 0, mean, near)
    return float(np.var(mean - ndimage.gaussian_filter(mean, nb / 16, mode="wrap")))


def test_r42_crop_xml_lattice_is_the_micro_image_borders(realdata):
    """Independent check that the XML's pitch and rotation describe this crop (it was not
    resized): the micro-image borders fold sharpest on the XML lattice (34.865 px, 0 deg);
    a fine scan of the same measure peaks at 34.87 +- 0.03 px, 0.00 +- 0.04 deg."""
    folder = realdata / "raytrix" / "r42_crop"
    flat = hexgrid.flatten(_load(folder / "sc2_klein.png"), scale_px=50.0)
    grad = np.hypot(cv2.Sobel(flat, cv2.CV_32F, 1, 0, ksize=1),
                    cv2.Sobel(flat, cv2.CV_32F, 0, 1, ksize=1))
    grad = np.minimum(grad, np.percentile(grad, 99))
    xml = raytrix.grid_from_calib(raytrix.read_calib(folder / "sc2_klein.xml"), grad.shape)
    pitch, angle = xml.pitch_px, np.degrees(xml.angle_rad)
    assert abs(pitch - 34.8647) < 1e-3 and abs(angle) < 1e-6
    at_xml = _border_contrast(grad, pitch, angle)
    # a scene periodicity (strongest raw fold), calibrate's past answers, and detunings
    others = {(32.35, 2.4): 0, (36.37, -0.1): 0, (33.94, 2.0): 0, (34.55, 0.74): 0}
    for dp, da in ((0.5, 0), (-0.5, 0), (0, 1.0), (0, -1.0), (1.5, 0), (-1.5, 0)):
        others[(pitch + dp, angle + da)] = 0
    for key in others:
        others[key] = _border_contrast(grad, *key)
    worst = max(others, key=others.get)
    assert at_xml >= 3.0 * others[worst], (at_xml, worst, others[worst])


def test_r42_crop_pitch_and_rotation(realdata):
    """A small scene crop (~19 lenses across its short side) whose intensity spectrum is
    dominated by repeated scene content: the border fold picks the lattice among the spectral
    hypotheses."""
    folder = realdata / "raytrix" / "r42_crop"
    image = _load(folder / "sc2_klein.png")
    grid, _ = hexgrid.calibrate(image)
    xml = raytrix.grid_from_calib(raytrix.read_calib(folder / "sc2_klein.xml"), image.shape)
    assert abs(grid.pitch_px - xml.pitch_px) <= 0.03
    step = np.pi / 3
    dang = (grid.angle_rad - xml.angle_rad + step / 2) % step - step / 2
    assert abs(np.degrees(dang)) <= 0.01
