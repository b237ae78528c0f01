"""A lens grid that does not fit the frame is refused, not used (docs/depth.md, "Grid check")."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from plenocli.depth.gridcheck import lattice_misfit
from tests.test_depth import _scene

WRONG = {
    "pitch +0.5 %": dict(pitch_factor=1.005),
    "pitch +3 %": dict(pitch_factor=1.03),
    "turned 2 deg": dict(turn=np.radians(2)),
    "turned 20 deg": dict(turn=np.radians(20)),
    "turned 30 deg (half the hex period)": dict(turn=np.radians(30)),
    "turned 35 deg": dict(turn=np.radians(35)),
    "square on hex": dict(lattice="square"),
    "another camera (x sqrt 3)": dict(pitch_factor=np.sqrt(3), turn=np.pi / 6),
}


def _variant(grid, pitch_factor=1.0, turn=0.0, lattice=None):
    return dataclasses.replace(grid, pitch_px=grid.pitch_px * pitch_factor,
                               angle_rad=grid.angle_rad + turn,
                               lattice=lattice or grid.lattice)


@pytest.mark.parametrize("g", [4.0, -4.0])
def test_the_frames_own_grid_fits(g):
    frame, grid, _ = _scene("plane", g=g, seed=2 if g < 0 else 0)
    assert lattice_misfit(frame, grid, for_depth=True) == (True, None)


@pytest.mark.parametrize("case", sorted(WRONG))
def test_a_grid_that_does_not_fit_is_refused_for_depth(case):
    frame, grid, _ = _scene("plane", g=4.0, seed=0)
    _, misfit = lattice_misfit(frame, _variant(grid, **WRONG[case]), for_depth=True)
    assert misfit is not None and "the grid" in misfit, case


def test_refocus_tolerates_what_a_fraction_of_a_pitch_allows():
    """Refocus needs the lattice within a quarter pitch at the corners: +0.5 % on this 480 px
    frame is 0.07 pitch (a slightly different g), +3 % is 0.43 pitch (a wrong image)."""
    frame, grid, _ = _scene("plane", g=4.0, seed=0)
    assert lattice_misfit(frame, _variant(grid, pitch_factor=1.005)) == (True, None)
    assert "pitches apart" in lattice_misfit(frame, _variant(grid, pitch_factor=1.03))[1]



def test_a_grid_far_off_is_not_said_to_be_what_the_frame_shows():
    """E3 (audit 6): another camera's XML (pitch x 1.73) was refused saying "the frame shows
    a hex 61.40 px at 10.90 deg lattice" (the fold, started from far off, settled on a coarse
    relative of the frame's 23.22 px lattice)."""
    frame, grid, _ = _scene("plane", g=4.0, seed=0)
    _, misfit = lattice_misfit(frame, _variant(grid, pitch_factor=1.726))
    assert misfit is not None and "do not lie on the grid's" in misfit
    assert "the frame shows" not in misfit


def test_another_cameras_fine_grid_on_a_lattice_it_cannot_fold_is_refused():
    """Audit 24b W6: a hex 6.3 px grid (another camera's) on frames of a 9.7 px white folded to
    nothing from its own lattice and was used unchecked ("no micro-image lattice"), though
    calibrate finds 9.7 px there at contrast 2.4: the frames' own lattice refuses it, also
    when the grid covers only a corner of them (its area: 11 lenses of the frames' pitch)."""
    from plenocli.model.lensgrid import LensGrid
    from plenocli.synth.whiteimage import white_image

    frame, _ = white_image((300, 420), pitch_px=9.7, angle_rad=np.radians(13),
                           offset_xy=(213.6, 148.0), seed=3)
    frame = frame.astype(np.float64)
    grid = LensGrid(6.3, np.radians(19), (130.3, 126.7), "hex", image_shape=(256, 256))
    shows, misfit = lattice_misfit(frame[:256, :256], grid, whole=lambda: frame)
    assert misfit is not None and "hex 9.70 px" in misfit and "hex 6.30 px" in misfit
    _, own = lattice_misfit(frame, dataclasses.replace(grid, image_shape=frame.shape))
    assert own is not None and "hex 9.70 px" in own
