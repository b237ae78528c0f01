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


@pytest.mark.xfail(reason="measured pitch 33.94 px vs XML 34.86 px, angle 2 deg off: not yet "
                   "understood (crop scale or lattice choice)", strict=False)
def test_r42_crop_pitch_and_rotation(realdata):
    folder = realdata / "raytrix" / "r42_crop"
    image = _load(folder / "sc2_klein.png")
    grid, _ = hexgrid.calibrate(image)
    xml = raytrix.grid_from_calib(raytrix.read_calib(folder / "sc2_klein.xml"), image.shape)
    assert abs(grid.pitch_px - xml.pitch_px) <= 0.1
    step = np.pi / 3
    dang = (grid.angle_rad - xml.angle_rad + step / 2) % step - step / 2
    assert abs(np.degrees(dang)) <= 0.05
