"""Does a lens grid fit the frame it is used on?

A grid or RayCalibData XML is a side file: it can belong to another camera, be a few per cent
off in pitch, turned, of the other lattice kind or written in other units. Depth and refocus
computed on such a grid are confidently wrong, so the grid is checked against what every lenslet
frame shows, with the calibration's own fold judge (:mod:`plenocli.calibration.fold`): folding
the frame onto the lens lattice gives a sharp mean micro-image; any other lattice (a relative,
the other kind, a copy detuned in pitch or angle) gives a flat or self-repeating one. The judge
is started from the grid's lattice and its other kind, and, when neither folds sharply, from the
grid's lattice turned by eighths of its symmetry period (7.5 deg for hex: a fold climbs back a
few degrees, not 30); the lattice it confirms must be the grid's kind and must not drift from
the grid's by more than ``MAX_DRIFT`` of a pitch anywhere in the frame (the error a pitch or
angle error makes at the frame's corners: 3 % in pitch on a 240 px frame is 0.18 pitches at the
corners, on a 4000 px frame 3 pitches).

The grid's offset (where its lens centres are) is measured for depth, not only checked: the
usable micro-image disc and its vignetting are centred on the grid's centres, and an offset
0.5 px off moved a plane at g = 4 to 4.3, 1 px off to 5.1 (simulator). The lens centre among the
lattice's symmetry points, by the turn symmetry of the frame's mean micro-image
(:func:`plenocli.calibration.centres.lens_centre`, what calibrate measures), says where they
are; :func:`centred` moves the grid onto it, and refuses a grid more than ``MAX_OFFSET`` of a
pitch off (another capture's or crop's: its lens indices, hence lens types, are not vouched
for).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from plenocli.model.lensgrid import LensGrid

MAX_DRIFT = 0.25      # pitches: where the grid's lattice and the frame's may part (refocus)
CHECK_PX = 1024         # side of the central region folded: a tenth of depth's time on 8 Mpx
CHECK_PITCHES = 24      # and at least this many lenses across (16 left Boys2 unsure)
MAX_DEPTH_ERROR = 0.002  # a lattice vector's error over the pitch, for depth (below)
TURN_STARTS = 8         # starts per symmetry period when the grid's own angle folds to nothing
FAR_ERROR = 0.2         # lattice vectors this far apart: the fold found a relative, maybe
MAX_OFFSET = 0.25       # pitches: a grid's centres this far from the micro-images are refused
REFIT_PRECISION = 0.05  # px at the corners: a regional lattice this sure replaces the grid's
DEPTH_CHECK_PITCHES = 10  # lenses across the folded region below which MAX_DEPTH_ERROR is not
#                           told: 4.7 across folded the true lattice 0.3-0.4 % off, 18 x 24 0.06 %
OWN_PX = 2048          # side of the central region searched for the frames' own lattice
OWN_MIN_PX = 48        # calibrate's least image side (calibration.MIN_SIDE_PX)
DEPTH_PRECISION = "depth precision"   # _disagreement's word for an error over MAX_DEPTH_ERROR


def lattice_misfit(frame: np.ndarray, grid: LensGrid, *, for_depth: bool = False,
                   whole: Callable[[], np.ndarray | None] | None = None
                   ) -> tuple[bool, str | None]:
    """(whether the frame (rows, cols; grey: the grid's area of the frames) shows ``grid``'s
    lattice, how it disagrees or None). Where the fold from the grid's lattice vouches for
    none, the frames are searched for a lattice of their own (:func:`frames_own`, on what
    ``whole()`` gives: all of the frames' grey, when the grid covers only a part of them,
    made only then); one that
    is not the grid's refuses it; where they show none either (a few lenses, micro-images
    without vignetting, a crop like the R42's), nothing contradicts the grid and it is used.

    Refocus needs the lattice right to a fraction of a pitch over the frame; depth reads g
    from the shift between neighbours, so an error e in a lattice vector (over the pitch) is
    an error of about e in 1/g (measured on the simulator: pitch +0.25 % moves g = 4 to 4.24,
    +0.5 % to 4.9): ``for_depth`` also bounds e.
    """
    from plenocli.calibration.candidates import Lattice
    from plenocli.calibration.fold import Folds, fold_judge

    own = Lattice(grid.lattice, grid.pitch_px, grid.angle_rad)
    other = Lattice("square" if own.kind == "hex" else "hex", own.pitch_px, own.angle_rad)
    side = int(max(CHECK_PX, CHECK_PITCHES * own.pitch_px))
    rows, cols = frame.shape
    top, left = max(0, (rows - side) // 2), max(0, (cols - side) // 2)
    centre = np.asarray(frame[top:top + side, left:left + side], np.float64)
    folds = Folds(np.nan_to_num(centre), own.pitch_px)
    found = fold_judge([own, other], folds).lattice
    if found is None:  # a grid turned too far for the fold to climb back: start from turns
        step = np.pi / 3 if own.kind == "hex" else np.pi / 2
        turns = [Lattice(own.kind, own.pitch_px, own.angle_rad + k * step / TURN_STARTS)
                 for k in range(1, TURN_STARTS)]
        found = fold_judge(turns, folds).lattice
    if found is None:   # the grid's lattice folds to nothing: what do the frames show?
        larger = whole() if whole is not None else None
        return False, _own_misfit(frame if larger is None else larger, own)
    misfit = _disagreement(frame, own, found, for_depth)
    if misfit == DEPTH_PRECISION and min(centre.shape) < DEPTH_CHECK_PITCHES * own.pitch_px:
        # a fold over a few lenses is not precise to MAX_DEPTH_ERROR: the simulator's own
        # grid on 95 x 95 px (4.7 lenses across) folded 0.39 % off; unchecked, not refused
        return False, None
    return True, (misfit if misfit != DEPTH_PRECISION else _depth_misfit(own, found))


def frames_own(frame: np.ndarray):
    """The lattice the frame (rows, cols; grey) shows on its own, by calibrate's judges on
    its central OWN_PX (:func:`plenocli.calibration.judges.decide`, no hint) and confirmed by
    a sharp fold on it, with the judges' account; (None, "") where none is vouched for.

    The grid check's fold starts from the grid's lattice: a lattice far from it (another
    camera's pitch) is out of its reach, so "nothing folds" says nothing about the frames
    (audit 24b W6: a 6.3 px grid on frames of a 9.7 px white, which calibrate finds at
    contrast 2.44, was used unchecked). The search itself proposes its lattices from the
    frame's spectrum and autocorrelation; the fold (scene content does not fold: it averages
    out over the micro-images) must confirm the judges' choice before it refuses a grid."""
    from plenocli.calibration.fold import Folds, fold_judge
    from plenocli.calibration.judges import decide
    from plenocli.calibration.search import views
    from plenocli.errors import CalibrationError

    rows, cols = frame.shape
    top, left = max(0, (rows - OWN_PX) // 2), max(0, (cols - OWN_PX) // 2)
    centre = np.nan_to_num(np.asarray(frame[top:top + OWN_PX, left:left + OWN_PX],
                                      np.float64))
    if min(centre.shape) < OWN_MIN_PX:
        return None, ""
    try:
        decision = decide(centre, views(centre, None))
    except CalibrationError:
        return None, ""
    fold = fold_judge([decision.lattice], Folds(centre, decision.lattice.pitch_px))
    if fold.lattice is None:
        return None, ""
    return fold.lattice, f"{decision.describe()}; fold sharpness {fold.sharpness:.3f}"


def _own_misfit(frame: np.ndarray, own) -> str | None:
    """How the lattice the frames show on their own (:func:`frames_own`) disagrees with the
    grid's (``own``): another kind, or vectors apart by more than MAX_DRIFT of a pitch at the
    frame's corners; None where they show none, the grid's or a relative of it (the fold from
    the grid's lattice would have settled a relative: nothing says which one is right)."""
    from plenocli.calibration.verify import nested

    found, account = frames_own(frame)
    if found is None or nested(own, found) is not None:
        return None
    error = _vector_error(own, found) if found.kind == own.kind else np.inf
    drift = error * float(np.hypot(*frame.shape)) / 2 / own.pitch_px
    if drift <= MAX_DRIFT:
        return None
    return (f"the frames show a {found.describe()} lattice of their own (calibrate's "
            f"judges on their centre: {account}), the grid says {own.describe()}")


def _disagreement(frame: np.ndarray, own, found, for_depth: bool) -> str | None:
    """How the lattice the frame shows (``found``) disagrees with the grid's (``own``)."""
    shows = f"the frame shows a {found.describe()} lattice, the grid says {own.describe()}"
    if found.kind != own.kind:
        return shows
    error = _vector_error(own, found)
    drift = error * float(np.hypot(*frame.shape)) / 2 / own.pitch_px
    if error > FAR_ERROR:   # folded from far off, the fold can settle on a coarse relative
        return (f"the frame's micro-images do not lie on the grid's {own.describe()} lattice "
                f"(folded from it they repeat on {found.describe()}, or a finer lattice "
                f"within it; {drift:.2f} pitches apart at the frame's corners)")
    if drift > MAX_DRIFT:
        return f"{shows} ({drift:.2f} pitches apart at the frame's corners)"
    if for_depth and error > MAX_DEPTH_ERROR:
        return DEPTH_PRECISION
    return None


def _depth_misfit(own, found) -> str:
    return (f"the frame shows a {found.describe()} lattice, the grid says {own.describe()} "
            f"(lattice vectors {100 * _vector_error(own, found):.2f} % apart; depth needs <= "
            f"{100 * MAX_DEPTH_ERROR:g} %)")


def _vector_error(own, found) -> float:
    """Largest |b_found - b_own| / pitch over the lattice vectors, ``found`` turned by whole
    lattice periods onto ``own``."""
    step = np.pi / 3 if own.kind == "hex" else np.pi / 2
    turn = (found.angle_rad - own.angle_rad + step / 2) % step - step / 2
    ratio = found.pitch_px / own.pitch_px
    return float(abs(ratio * np.exp(1j * turn) - 1))


def centred(frame: np.ndarray, grid: LensGrid, *, refit: bool = False
            ) -> tuple[LensGrid, tuple[float, float] | None]:
    """``grid`` moved onto the lens centres the frame (rows, cols; grey) shows, and the move
    (dx, dy) px; the grid as it is and None where the mean micro-image is not clearly round
    about one symmetry point (a devignetted frame: nothing contradicts the grid). ValueError
    when the grid's centres are more than MAX_OFFSET of a pitch from the frame's. ``refit``
    (depth) also refits a lattice-only grid's pitch and angle on the frame
    (:func:`refitted`)."""
    from dataclasses import replace

    from plenocli.calibration.centres import lens_centre
    from plenocli.calibration.flatten import flatten

    flat = np.nan_to_num(flatten(np.nan_to_num(frame)))
    found = lens_centre(flat, grid)
    if not found.sure:
        return grid, None
    x, y = found.offset_xy
    dx, dy = np.array([x, y]) - grid.lattice_xy(*grid.nearest_index(x, y))
    if np.hypot(dx, dy) > MAX_OFFSET * grid.pitch_px:
        raise ValueError(f"its lens centres lie {np.hypot(dx, dy):.1f} px from the frame's "
                         f"micro-images (more than {MAX_OFFSET:g} of the {grid.pitch_px:.4g} px "
                         "pitch): it is another capture's or crop's grid")
    centres = None if grid.centres_xy is None else np.asarray(grid.centres_xy) + (dx, dy)
    moved = replace(grid, offset_xy=(grid.offset_xy[0] + dx, grid.offset_xy[1] + dy),
                    centres_xy=centres)
    return (refitted(flat, moved) if refit else moved), (float(dx), float(dy))


def refitted(flat: np.ndarray, grid: LensGrid) -> LensGrid:
    """A lattice-only ``grid`` with the pitch, angle and offset of the lattice through the
    lens centres of the frame's regions (:func:`plenocli.calibration.fit.regional_lattice`:
    each region's mean micro-image, scene content averaged out), where that lattice places
    the frame's corner lenses to REFIT_PRECISION px; else ``grid`` as it is.

    Depth needs the lens centres to about a tenth of a pixel over the whole frame: an error e
    in a lattice vector moves the lenses at the corners by e times the half-diagonal, which
    the fold check (MAX_DEPTH_ERROR, from the middle region) cannot tell on a large frame:
    pitch 0.05-0.15 % off (0.2-0.6 px at the corners of 480 x 640, 1.2 px at those of 8 Mpx)
    read a plane at g = 4 with median errors 0.04-0.33 (8 Mpx: 1.8). The regions' lattice
    places the corner lenses to 0.003-0.03 px (simulator, 480 x 640 to 1200 x 1600). A grid
    that lists its centres (calibrate's, measured lens by lens) is used as it lists them."""
    from dataclasses import replace

    from plenocli.calibration.fit import regional_lattice

    if grid.centres_xy is not None:
        return grid
    found = regional_lattice(flat, grid)
    if found is None:
        return grid
    pitch, angle, offset, (pitch_se, angle_se) = found
    half_diagonal = float(np.hypot(*flat.shape)) / 2
    if half_diagonal * (pitch_se / pitch + angle_se) > REFIT_PRECISION:
        return grid
    return replace(grid, pitch_px=float(pitch), angle_rad=float(angle),
                   offset_xy=(float(offset[0]), float(offset[1])))
