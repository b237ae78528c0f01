"""Side files checked against the data they claim to describe, as a stage's one-line error."""

from __future__ import annotations

import numpy as np

from plenocli.depth.gridcheck import centred, lattice_misfit
from plenocli.errors import InputError


def check_fits(frame: np.ndarray, grid, grid_path: str, *, for_depth: bool = False) -> None:
    """InputError saying how ``grid`` (read from ``grid_path``) disagrees with the frame
    (docs/depth.md, "Grid check"); depth and refocus call it before using a grid."""
    misfit = lattice_misfit(frame, grid, for_depth=for_depth)
    if misfit:
        raise InputError(f"{grid_path} does not fit the frames: {misfit}; make the grid with "
                         "`plenocli calibrate` on a white image (or these frames)")


def centred_on(frame: np.ndarray, grid, grid_path: str):
    """(grid moved onto the frame's lens centres, the move (dx, dy) px or None where the frame
    does not show them); InputError for a grid more than a quarter pitch off (depth)."""
    try:
        return centred(frame, grid)
    except ValueError as err:
        raise InputError(f"{grid_path} does not fit the frames: {err}; make the grid with "
                         f"`plenocli calibrate --start {grid_path}` on these frames") from err
