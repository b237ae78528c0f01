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
