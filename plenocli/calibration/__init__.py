"""Micro-lens grid calibration from one lenslet image (white image or scene).

The method, as ``calibrate`` reads:

1. **Views** (``search``, ``flatten``): the central part of the image at decimations 1, 2, 4, 8,
   flattened (vignetting and scene brightness divided out), with its border signal (gradient
   magnitude: the micro-image borders are edges in every lenslet image).
2. **Hypotheses** (``candidates``): every peak of their spectra, read as a hex and a square
   lattice, with the relatives it could belong to (x2, /2, x sqrt(3) / sqrt(2) turned, the other
   kind).
3. **Verdict** (``verify``): each hypothesis is judged by the autocorrelation of the border
   signal at long lags (lattice points must all be peaks and every hole a trough, as far as the
   frame reaches); the winner must clearly beat every unrelated hypothesis and its own detuned
   copies, or the calibration is refused naming the rivals.
4. **Centres and lattice** (``centres``, ``fit``): the lens centres are where the frame's mean
   micro-image (every pixel folded into one lattice cell) keeps the lattice's full turn
   symmetry (holes and edge midpoints do not); then every micro-image's point-symmetry centre
   and a robust least-squares lattice through them (on a scene: the border lattice, bent by
   the smooth field of the regions' mean micro-images).
5. **Lens types** (``lenstypes``): for a hex array, whether the three cosets of the index-3
   sub-lattice differ in sharpness (a multi-focus array), and which is which.

Coordinates: x = column, y = row (down), pixel centres at integers; see ``plenocli.model.lensgrid``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from plenocli.calibration.candidates import Lattice
from plenocli.calibration.centres import (
    LensCentre,
    lens_centre,
    refine_centres,
)
from plenocli.calibration.fit import LatticeFit, compare_grids, fit_grid, fit_lattice
from plenocli.calibration.flatten import flatten
from plenocli.calibration.lenstypes import classify
from plenocli.calibration.search import border_lattice, find_lattice, hypotheses, view_for, views
from plenocli.calibration.verify import Verdict, control_contrast, doubt, judge
from plenocli.errors import CalibrationError
from plenocli.model.lensgrid import LATTICES, LensGrid

__all__ = ["CalibrationReport", "calibrate", "compare_grids", "fit_lattice", "flatten",
           "refine_centres"]

MIN_SIDE_PX = 48       # smaller images cannot hold a lattice worth fitting
# a lattice read from the border repetition is used when its pitch and angle errors move the
# frame's corner lenses by at most this share of a pitch
CORNER_TOLERANCE = 0.05
FEW_LENSES_ACROSS = 20  # below this many lenses across, a failure says the image is small


@dataclass(frozen=True)
class CalibrationReport:
    """What the calibration found and how sure it is."""

    fit: LatticeFit
    verdict: Verdict
    lens_types: dict | None = None
    lens_centre: LensCentre | None = None

    def to_dict(self) -> dict:
        return {**{k: (v if isinstance(v, bool) else float(v) if isinstance(v, float)
                       else int(v)) for k, v in self.fit.__dict__.items()},
                "confidence": self.verdict.to_dict(), "lens_types": self.lens_types,
                "lens_centre": self.lens_centre.to_dict() if self.lens_centre else None}


def calibrate(image: np.ndarray, *, lattice: str = "auto", cfa: str | None = None,
              black_level: float = 0.0, pitch_hint: float | None = None,
              start: LensGrid | None = None) -> tuple[LensGrid, CalibrationReport]:
    """Estimate the micro-lens lattice and every micro-image centre from one image.

    Parameters
    ----------
    image : (rows, cols) array
        A white image (best) or a scene taken through the lens array; a raw Bayer mosaic is
        fine when ``cfa`` names the pattern at pixel (0, 0).
    lattice : "auto", "hex" or "square"; a kind that does not fit the image is refused
    black_level : DN subtracted first
    pitch_hint : approximate pitch (px), e.g. from a datasheet: only lattices within 15 %
    start : a grid to refine (a camera calibration): its lattice is checked, not searched

    Returns
    -------
    grid : LensGrid with angle_rad in one lattice period, offset_xy = the lens nearest the image
        centre, ``centres_xy`` / ``indices`` of every lens inside the image, and the lens types
        of a multi-focus array.
    report : residuals, the confidence (contrast, rivals) and the lens types.

    Raises
    ------
    CalibrationError when no lattice can be vouched for (with the rivals and what to do).
    """
    image = _checked(image, lattice, black_level, pitch_hint)
    all_views = views(image, cfa)
    if start is None:
        verdict = find_lattice(all_views, hypotheses(all_views, pitch_hint=pitch_hint))
    else:
        verdict = _start_verdict(start, all_views)
    reason = doubt(verdict)
    if reason and start is not None:
        raise CalibrationError(f"the start grid ({verdict.lattice.describe()}) does not fit this "
                               f"image: {reason}; check the --start file or calibrate without it")
    if reason:
        raise CalibrationError(f"{reason}; {_what_to_do(image.shape, pitch_hint)}")
    found = verdict.lattice
    if lattice != "auto" and found.kind != lattice:
        raise CalibrationError(f"--lattice {lattice} does not fit this image: it shows a "
                               f"{found.describe()} lattice; use --lattice {found.kind} or auto")
    border = border_lattice(found, all_views)
    sure = _corner_error(border, image.shape) <= CORNER_TOLERANCE * found.pitch_px
    if sure:
        found = border.lattice
    flat = flatten(image, cfa=cfa, scale_px=max(1.5 * found.pitch_px, 8.0))
    centre = lens_centre(flat, LensGrid(found.pitch_px, found.angle_rad, (0.0, 0.0), found.kind))
    if not centre.sure:
        raise CalibrationError(
            f"{found.describe()} lattice found, but its lens centres cannot be told from the "
            f"holes between them (the mean micro-image is as round about a hole: asymmetry "
            f"{centre.asymmetry:.2f} against {centre.rival_asymmetry:.2f}); "
            f"{_what_to_do(image.shape, pitch_hint, found.pitch_px)}")
    guess = LensGrid(found.pitch_px, found.angle_rad, centre.offset_xy, found.kind,
                     image_shape=image.shape)
    grid, fit = fit_grid(flat, guess, border=(found.pitch_px, found.angle_rad,
                                              border.pitch_err_px, border.angle_err_rad)
                         if sure else None)
    if not fit.centres_refined and not sure:
        raise CalibrationError(
            f"{found.describe()} lattice found, but on this scene neither the micro-image "
            f"centres nor the border repetition pin its pitch down (+-{border.pitch_err_px:.3f} "
            f"px); {_what_to_do(image.shape, pitch_hint, found.pitch_px)}")
    types = classify(flat, grid.indices, grid.centres_xy, grid.pitch_px) \
        if grid.lattice == "hex" else None
    type_info = None
    if types is not None:
        coset = tuple(int(types.types[np.flatnonzero(
            (grid.indices[:, 0] - grid.indices[:, 1]) % 3 == k)[0]]) for k in range(3))
        grid = LensGrid(grid.pitch_px, grid.angle_rad, grid.offset_xy, grid.lattice,
                        image_shape=grid.image_shape, centres_xy=grid.centres_xy,
                        indices=grid.indices, lens_type_of_coset=coset)
        type_info = {"type_of_coset": list(coset), "sharpness": list(types.sharpness),
                     "p_value": types.p_value}
    return grid, CalibrationReport(fit=fit, verdict=verdict, lens_types=type_info,
                                   lens_centre=centre)


def _what_to_do(shape: tuple[int, int], pitch_hint: float | None,
                pitch_seen: float | None = None) -> str:
    """What could make the image calibrate: the hints not given yet, a larger image when it
    holds few lenses across."""
    hints = ([] if pitch_hint else ["--pitch PX (approximate)"]) + [
        "a white image", "--start GRID.yaml|calib.xml"]
    advice = f"pass {', '.join(hints[:-1])} or {hints[-1]}"
    pitch = pitch_hint or pitch_seen
    across = min(shape) / pitch if pitch else None
    if across is not None and across < FEW_LENSES_ACROSS:
        return (f"the {shape[1]} x {shape[0]} px image holds only {across:.0f} lenses of "
                f"{pitch:.1f} px across: calibrate on a larger image, or {advice}")
    return advice


def _corner_error(border, shape: tuple[int, int]) -> float:
    """How far (px) the uncertainty of a border lattice moves the lenses at the frame corners."""
    half_diagonal = float(np.hypot(*shape)) / 2
    return half_diagonal * (border.pitch_err_px / border.lattice.pitch_px + border.angle_err_rad)


def _checked(image: np.ndarray, lattice: str, black_level: float,
             pitch_hint: float | None) -> np.ndarray:
    if lattice not in ("auto", *LATTICES):
        raise ValueError(f"lattice must be 'auto' or one of {sorted(LATTICES)}, got {lattice!r}")
    if pitch_hint is not None and not 4.0 <= pitch_hint <= 200.0:
        raise ValueError(f"pitch_hint must be 4-200 px, got {pitch_hint}")
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError(f"image must be 2-D (rows, cols), got shape {image.shape}")
    rows, cols = image.shape
    if min(rows, cols) < MIN_SIDE_PX:
        raise CalibrationError(f"image of {cols} x {rows} px is too small to calibrate a lens "
                               f"grid; it needs at least {MIN_SIDE_PX} px on each side")
    image = image.astype(np.float32, copy=False)
    if black_level:
        image = image - np.float32(black_level)
    if not np.isfinite(image).all():
        raise CalibrationError("the image holds NaN or infinite values; pass a decoded frame")
    return image


def _start_verdict(start: LensGrid, all_views) -> Verdict:
    """The confidence of a given lattice: its border contrast against its detuned copies and
    its relatives (a start file off by a harmonic is refused like a search would be)."""
    own = Lattice(start.lattice, start.pitch_px, start.angle_rad)
    scored = [(lat, view_for(lat, all_views).acf.contrast(lat))
              for lat in [own, *own.relatives()]]
    verdict = judge(scored, lambda lat: view_for(lat, all_views).acf)
    verdict = replace(verdict, control=control_contrast(own, view_for(own, all_views).acf))
    if not verdict.lattice.same_as(own):   # the start file is a relative of the lattice
        return Verdict(own, scored[0][1], ((verdict.lattice, verdict.contrast),),
                       verdict.control, undecided=True)
    return verdict
