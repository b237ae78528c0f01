"""Side files checked against the data they claim to describe, as a stage's one-line error."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from plenocli.depth.gridcheck import centred, lattice_misfit
from plenocli.errors import InputError
from plenocli.io.gridfile import measured_on, vouched_by
from plenocli.model.provenance import sha256_file
from plenocli.progress import log


def check_fits(frame: np.ndarray, grid, grid_path: str, *, frames_path: str | None = None,
               for_depth: bool = False, stored_only: bool = False,
               whole: Callable[[], np.ndarray | None] | None = None) -> bool:
    """InputError saying how ``grid`` (read from ``grid_path``) disagrees with the frame
    (docs/depth.md, "Grid check"); depth, refocus and crosstalk call it before using a grid.
    Returns whether the grid is checked: the frame shows its lattice, or the grid was
    calibrated on the file ``frames_path`` itself. A grid the frames cannot check is used only
    when its record vouches for it (:func:`unvouched`), else refused; then the stage says it
    is used unchecked (:func:`warn_unchecked`) and records it. ``stored_only``: the grid is
    stored with the frames as theirs (decode --calib): only a grid the frames check is.
    ``whole``: gives the grey of all of the frames where the grid covers only a part of them
    (``frame``), searched for the frames' own lattice
    (:func:`plenocli.depth.gridcheck.frames_own`) when the grid's own lattice folds to
    nothing."""
    if not stored_only and not np.isfinite(frame).any():
        # nothing under the grid to check it with, or to use it on: the frames are the fault
        raise InputError(f"{frames_path or 'the frames'}: no valid pixel under the grid (all "
                         "NaN: masked or clipped); check how the frames were made")
    shows, misfit = lattice_misfit(frame, grid, for_depth=for_depth, whole=whole)
    if misfit:
        raise InputError(f"{grid_path} does not fit the frames: {misfit}; make the grid with "
                         "`plenocli calibrate` on a white image (or these frames)")
    if not shows and frames_path is not None:
        shows = sha256_file(frames_path) in measured_on(grid_path)
    if not shows and stored_only:
        # kept as the frames' calibration, every later reader would take it for theirs
        raise InputError(f"{grid_path}: the frames show no micro-image lattice to check it "
                         "against, so it cannot be stored as their calibration (another "
                         "camera's would pass unseen); decode without --calib, and calibrate "
                         "the grid from a white image of the same camera")
    if not shows:
        unvouched(grid_path)
    return shows


def beyond_grid(framing, pages: np.ndarray, *, mosaic: bool) -> np.ndarray | None:
    """The grey of all of ``pages`` (P, rows, cols) where the grid's area (``framing``) is
    only a part of them (a grid calibrated on a crop), for :func:`check_fits` ``whole`` (as
    ``functools.partial(beyond_grid, ...)``: made only when needed); None where it covers
    them all. A few lenses of the grid's area may show no lattice that
    the whole frames show (audit 24b W6: a 256 x 256 grid on a 1001 x 777 origami crop)."""
    if framing.shape == tuple(pages.shape[-2:]):
        return None
    from plenocli.depth.lenslet import sensor_grey

    return sensor_grey(pages, mosaic=mosaic)


def unvouched(grid_path: str) -> None:
    """Refuse a grid the frames cannot check (no micro-image lattice shows: no vignetting, a
    devignetted capture, a few lenses) unless its record vouches for it: written by calibrate
    or simulate and unchanged since. There a grid 1 % off in pitch (audit 19 W2) shifts every
    pair of neighbouring micro-images alike, as a change of the scene's depth does: depth read
    a plane at g = 4 > 0.5 wrong on 17-35 % of it and refocus correlated 0.76 with the true
    grid's, with the micro-images matching their neighbours as clearly as on the true grid."""
    stage, why = vouched_by(grid_path)
    if stage is None:
        raise InputError(f"{grid_path}: the frames show no micro-image lattice to check this "
                         f"grid against, and {why}: nothing vouches for it; calibrate the "
                         "grid from a white image of the same camera (plenocli calibrate "
                         "WHITE.tif -o GRID.yaml) and give that file unchanged")


def warn_unchecked(grid_path: str) -> None:
    log.warning("%s: the frames' centre shows no micro-image lattice the grid check can vouch "
                "for (too few lenses, micro-images without vignetting or overlapping): it is "
                "used unchecked; make sure it is this camera's grid (plenocli calibrate on these "
                "frames or on the camera's white image)", grid_path)


def weak_match(stage: str, grid_path: str, median: float, clear: float) -> InputError:
    """The refusal of a grid the frames cannot check (no lattice shows) whose micro-images
    match their neighbours only weakly on it: on its own lattice they match clearly (median
    lens confidence 0.98 on the simulator's scene); turned 1-7 deg, 2-4 % off in pitch or
    another camera's, neighbours are compared at wrong offsets and the median falls to 0.3-0.4
    (depth's g off by 0.3-0.6, a refocused image at correlation 0.5 with the scene)."""
    return InputError(f"{stage}: the frames show no micro-image lattice to check {grid_path} "
                      f"against, and their micro-images match their neighbours on it only "
                      f"weakly (median lens confidence {median:.2f}, below {clear:g}): the "
                      "grid is likely not this camera's; make it with `plenocli calibrate` on "
                      "this camera's white image")


def centred_on(frame: np.ndarray, grid, grid_path: str, *, refit: bool = False):
    """(grid moved onto the frame's lens centres, the move (dx, dy) px or None where the frame
    does not show them); InputError for a grid more than a quarter pitch off (depth).
    ``refit``: a lattice-only grid's pitch and angle are refitted on the frame too (depth)."""
    try:
        return centred(frame, grid, refit=refit)
    except ValueError as err:
        raise InputError(f"{grid_path} does not fit the frames: {err}; make the grid with "
                         f"`plenocli calibrate --start {grid_path}` on these frames") from err
