"""The match judge (calibration/match.py): a start grid on a frame whose micro-images carry no
border in intensity (a devignetted, "processed" frame: divided by its white image, no gaps)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from plenocli import calibration
from plenocli.errors import CalibrationError
from plenocli.model.lensgrid import LensGrid
from plenocli.refocus import output_shape
from plenocli.synth.depthscene import lenslet_depth_frame, scene_planes
from plenocli.synth.lenslet import micro_image_mask

SHAPE = (480, 640)


@pytest.fixture(scope="module")
def processed():
    truth = LensGrid(23.2, 0.2, (321.3, 237.8), "hex", image_shape=SHAPE)
    planes = scene_planes("steps", output_shape(SHAPE, 0.2))
    frame = lenslet_depth_frame(truth, SHAPE, planes, s=0.2, seed=3, fill=1.15, falloff=0.3)
    return frame / micro_image_mask(truth, SHAPE, fill=1.15, falloff=0.3), truth


def test_a_start_half_a_lens_off_lands_on_the_lenses(processed):
    frame, truth = processed
    with pytest.raises(CalibrationError):   # nothing but the content's jumps shows the lenses
        calibration.calibrate(frame)
    start = replace(truth, offset_xy=(321.3 + 11.6, 237.8))
    grid, report = calibration.calibrate(frame, start=start)
    assert report.decision.judge == "match"
    _, centres = truth.lens_centres()
    i, j = grid.nearest_index(centres[:, 0], centres[:, 1])
    miss = np.linalg.norm(grid.lattice_xy(i, j) - centres, axis=1).max()
    assert miss <= 0.3, miss   # measured 0.05 px
    moved = calibration.moved_from_start(grid, start, report)
    assert moved["pitch"]["source"] == calibration.KEPT and "match" in moved["offset"]["source"]


def test_a_start_off_in_pitch_is_refused(processed):
    """0.5 % off: the corner lenses 0.07 pitch out; the match peaks 0.37 % below it."""
    frame, truth = processed
    with pytest.raises(CalibrationError, match="best at a pitch -0.[2-5]"):
        calibration.calibrate(frame, start=replace(truth, pitch_px=23.2 * 1.005))


@pytest.mark.slow
def test_a_pitch_hint_on_a_borderless_scene_is_measured_where_the_match_falls():
    """Audit 12 W6: the Raytrix scene simulator at hex 14.5 px (no micro-image borders: only
    the match judge sees the lattice). --pitch 14.5 was written as 14.5379 px (+0.26 %, the
    corner lenses 1.09 px off, exit 0): the top of the match curve leans towards larger
    pitches, and a parabola through it followed the lean. The midpoint of its falls is the
    lattice: 14.5016 px, every lens within 0.10 px. A start at the former answer is refused."""
    from plenocli.synth.focused import raytrix_scene

    image, truth, _, _ = raytrix_scene(seed=0, pitch_px=14.5)
    grid, report = calibration.calibrate(image, pitch_hint=14.5)
    assert report.decision.judge == "match"
    assert abs(grid.pitch_px / 14.5 - 1) <= 0.001, grid.pitch_px   # measured +0.011 %
    assert calibration.compare_grids(grid, truth, SHAPE)["max_px"] <= 0.05 * 14.5
    with pytest.raises(CalibrationError, match="best at a pitch -0.[1-4]"):
        calibration.calibrate(image, start=replace(truth, pitch_px=14.5379))
