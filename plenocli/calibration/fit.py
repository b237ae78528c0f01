"""Lattice fit through lens centres, re-indexing, and the comparison of two grids."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plenocli.calibration.centres import (
    asymmetries,
    asymmetry_parts,
    refine_centres,
    regional_shifts,
)
from plenocli.errors import CalibrationError
from plenocli.model.lensgrid import FIELD_DEGREE, FIELD_MAX, LATTICES, LensGrid, fit_lattice

MIN_LENSES = 12   # fewer whole micro-images: no lattice worth fitting


def lattice_from_lags(lags: np.ndarray, indices: np.ndarray, weights: np.ndarray, *,
                      lattice: str) -> tuple[float, float, tuple[float, float]]:
    """Pitch (px), angle (rad) and their standard errors of the similarity lattice whose
    vectors k b1 + m b2 best fit measured lags (K, 2) (the autocorrelation peaks)."""
    pitch, angle, _, se = fit_lattice(np.vstack([indices, -indices]),
                                      np.vstack([lags, -lags]), lattice=lattice,
                                      weights=np.concatenate([weights, weights]), return_se=True)
    # each peak enters twice (with its mirror image, which pins the lattice to the origin), but
    # a mirror image is no new measurement: counted once, the variances are twice the fit's
    return pitch, angle, (se[0] * np.sqrt(2.0), se[1] * np.sqrt(2.0))


def reindexed(pitch: float, angle: float, offset: tuple[float, float], lattice: str,
               shape: tuple[int, int]) -> LensGrid:
    """The same lattice with its angle in [0, step) and lens (0, 0) nearest the image centre."""
    step = LATTICES[lattice]
    k = np.floor(angle / step)
    angle_red = angle - k * step
    grid = LensGrid(pitch, angle_red, offset, lattice, image_shape=shape)
    rows, cols = shape
    i, j = grid.nearest_index((cols - 1) / 2, (rows - 1) / 2)
    centre = grid.lattice_xy(i, j)
    return LensGrid(pitch, angle_red, (float(centre[0]), float(centre[1])), lattice,
                    image_shape=shape)


def compare_grids(ours: LensGrid, other: LensGrid, image_shape: tuple[int, int]) -> dict:
    """Distance between two grids over every lens of ``ours`` inside the image (px).

    Each of our centres is paired with the nearest centre of ``other`` (its lattice, or its
    refined centres when it has them). Returns rms_px, max_px, mean shift (dx, dy) px, count,
    and the pitch and angle differences (angle modulo the lattice period).
    """
    grid = ours if ours.image_shape else LensGrid(ours.pitch_px, ours.angle_rad, ours.offset_xy,
                                                  ours.lattice, image_shape=image_shape)
    _, mine = grid.lens_centres() if ours.centres_xy is None else \
        (ours.indices, ours.centres_xy)
    if other.centres_xy is not None:
        from scipy.spatial import cKDTree

        _, k = cKDTree(other.centres_xy).query(mine)
        theirs = other.centres_xy[k]
    else:
        i, j = other.nearest_index(mine[:, 0], mine[:, 1])
        theirs = other.lattice_xy(i, j)
    d = mine - theirs
    dist = np.linalg.norm(d, axis=1)
    step = LATTICES[ours.lattice]
    dang = (ours.angle_rad - other.angle_rad + step / 2) % step - step / 2
    return {"lenses": int(len(dist)), "rms_px": float(np.sqrt(np.mean(dist ** 2))),
            "max_px": float(dist.max()), "mean_shift_xy": [float(v) for v in d.mean(axis=0)],
            "pitch_diff_px": float(ours.pitch_px - other.pitch_px),
            "angle_diff_deg": float(np.degrees(dang))}


@dataclass(frozen=True)
class LatticeFit:
    """How well the per-lens centres fit the lattice (pixels)."""

    lenses_total: int
    lenses_refined: int
    outliers: int
    residual_rms_px: float
    residual_max_px: float
    centres_refined: bool   # False: scene content moved the centres; they are the lattice's
    pitch_se_px: float = 0.0
    angle_se_rad: float = 0.0
    not_round: int = 0      # measured centres not written: the micro-image is not round about it


# median asymmetry (centres.asymmetries over the inner SCENE_INNER of a SYMMETRY_WINDOW
# disc) above which micro-images hold a scene: SCENE_ASYMMETRY + SCENE_SAMPLING / pitch^2, the
# second term for the bilinear mirror of few pixels. Simulated whites (pitch 6-38 px, Bayer or
# not, jitter 0-0.3 px) measured about half of it (0.0013 at 36 px, 0.0018 at 20, 0.0078 at
# 6.2); the lenslet-depth scene 0.010 at 20.2 px (threshold 0.0052), the Raytrix scene
# simulator 0.21, real Raytrix scenes 0.40-0.47
SCENE_ASYMMETRY = 0.004
SCENE_SAMPLING = 0.5
SCENE_INNER = 0.6
SYMMETRY_WINDOW = 0.6   # radius (pitches) of the disc each centre is the symmetry centre of
# a white's micro-image whose asymmetry about its own symmetry centre (``_not_round``) exceeds
# this many times the frame's median is not round about it: cut by a mask, a dead row or a
# hot column, its symmetry centre is not its lens's (audit 18 W6: up to 1.6 px off). Whole
# micro-images of simulated whites, with noise, vignetting or jitter, stay within 2.3 x the
# median (99.9th percentile; the tests' lens jittered 2.6 px off, 2-3.5 x); cut ones 4-3000 x
NOT_ROUND_RATIO = 4.0
CORE_PITCHES = 12.0     # the first fit uses lenses within this many pitches of the middle


def fit_grid(flat: np.ndarray, guess: LensGrid, *,
             border: tuple[float, float, float, float] | None = None
             ) -> tuple[LensGrid, LatticeFit]:
    """The lattice through the point-symmetry centres of the micro-images, from ``guess``.

    A first fit over the lenses near the middle corrects the pitch and rotation before the
    whole frame is refined (a 0.5 % pitch error is half a lens 100 lenses out). Lenses whose
    centre is far from the lattice (dead pixels, a bright scene edge) are dropped, robustly.
    When the residuals are large the image is a scene whose content moves the centres (they
    are not point-symmetric): then pitch and angle are those of ``border`` (pitch, angle and
    their standard errors, measured from the border repetition, when given), the offset is
    the guess's (the centre of the frame's mean micro-image, see :func:`lens_centre`), and the
    centres written are the lattice's moved by a smooth field through the centres of the
    regions' mean micro-images (:func:`smooth_field`; a camera's array and main lens bend the
    lattice by a few tenths of a pixel)."""
    rows, cols = flat.shape
    grid = reindexed(guess.pitch_px, guess.angle_rad, guess.offset_xy, guess.lattice,
                     (rows, cols))
    for core in (CORE_PITCHES, None):
        mid = grid.lattice_xy(0, 0)
        # a centre moves by under 0.3 pitch: lenses farther out cannot enter the core
        near = None if core is None else (mid, (core + 0.5) * grid.pitch_px)
        idx, centres, refined = refine_centres(flat, grid, window=SYMMETRY_WINDOW, near=near)
        if core is not None:
            refined = refined & (np.hypot(*(centres - mid).T) <= core * grid.pitch_px)
        if int(refined.sum()) < MIN_LENSES:
            raise CalibrationError(f"only {int(refined.sum())} whole micro-images fit in the "
                                   f"{cols} x {rows} px image (pitch {grid.pitch_px:.1f} px); "
                                   "use a larger image")
        grid, use, se = _robust_fit(idx, centres, refined, grid)
    # a white's micro-images are round about their own centres, wherever the lenses sit (a
    # jittered array leaves large residuals from the lattice, yet each centre is measured); a
    # scene's are not, and its content moves the centres the symmetry fit finds
    asymmetry = asymmetries(flat, centres[refined], SYMMETRY_WINDOW * grid.pitch_px,
                            inner=SCENE_INNER)
    scene = (float(np.nanmedian(asymmetry))
             > SCENE_ASYMMETRY + SCENE_SAMPLING / grid.pitch_px ** 2)
    if scene and border is not None:
        grid = reindexed(*border[:2], guess.offset_xy, grid.lattice, (rows, cols))
        se = border[2:]
    idx_out, ideal = grid.lens_centres()
    if scene:   # the lattice, bent by the smooth field of the regions' mean micro-images
        ideal = ideal + smooth_field(*regional_shifts(flat, grid), ideal, (rows, cols),
                                     grid.pitch_px)
    # every measured centre is written, also those the lattice fit left out as far from the
    # lattice (a lens set off by 2.6 px was written at its lattice place), but not one about
    # which its micro-image is not round (a jittered lens's is: it keeps its own centre)
    cut = np.zeros_like(refined) if scene else _not_round(flat, centres, refined,
                                                           grid.pitch_px)
    final, measured = _on_grid(grid, idx_out, ideal, centres, refined & ~cut)
    resid = np.linalg.norm(final - ideal, axis=1)[measured]
    report = LatticeFit(lenses_total=len(idx_out), lenses_refined=int(refined.sum()),
                        outliers=int((refined & ~use).sum()),
                        residual_rms_px=float(np.sqrt(np.mean(resid ** 2))),
                        residual_max_px=float(resid.max(initial=0.0)),
                        centres_refined=not scene, pitch_se_px=se[0], angle_se_rad=se[1],
                        not_round=int(cut.sum()))
    return LensGrid(grid.pitch_px, grid.angle_rad, grid.offset_xy, grid.lattice,
                    image_shape=(rows, cols), centres_xy=ideal if scene else final,
                    indices=idx_out), report


def _not_round(flat: np.ndarray, centres: np.ndarray, refined: np.ndarray,
               pitch: float) -> np.ndarray:
    """(K,) which refined centres their micro-image is not round about: its squared
    difference from its mirror image within SCENE_INNER of the disc (its own micro-image:
    farther out, the rims of a jittered lens's neighbours come in unevenly), over its own
    variance or over the frame's typical one (a hot column inflates its own), above
    NOT_ROUND_RATIO x the frame's median; or a disc with under 1 / NOT_ROUND_RATIO of the
    typical variance (a lens mostly in the dark), or none measured."""
    if not refined.any():
        return refined
    own, spread = asymmetry_parts(flat, centres[refined], SYMMETRY_WINDOW * pitch,
                                  inner=SCENE_INNER)
    typical = float(np.nanmedian(spread))
    out = ~(spread >= typical / NOT_ROUND_RATIO)
    for asym in (own, own * spread / typical):
        out |= ~(asym <= NOT_ROUND_RATIO * np.nanmedian(asym))
    cut = np.zeros_like(refined)
    cut[refined] = out
    return cut


REGION_TILES = 4       # regions per side whose mean micro-images place the lattice


def regional_lattice(flat: np.ndarray, grid: LensGrid, measured: tuple | None = None
                     ) -> tuple | None:
    """Pitch, angle, offset and their standard errors (pitch px, angle rad) of the lattice
    through the lens centres of the mean micro-images of REGION_TILES x REGION_TILES regions
    (:func:`regional_shifts`: scene content averaged over each region's lenses), robustly
    (regions beyond 4 robust sigma dropped once); None when fewer than FIELD_REGIONS regions
    show a round mean micro-image. ``measured``: the regions' (middles, shifts) when known."""
    middles, shifts = measured or regional_shifts(flat, grid, tiles=REGION_TILES)
    if len(shifts) < FIELD_REGIONS:
        return None
    i, j = grid.nearest_index(middles[:, 0] + shifts[:, 0], middles[:, 1] + shifts[:, 1])
    idx = np.stack([i, j], axis=1)
    points = grid.lattice_xy(i, j) + shifts
    use = np.ones(len(points), bool)
    for _ in range(2):
        pitch, angle, offset, se = fit_lattice(idx[use], points[use], lattice=grid.lattice,
                                               return_se=True)
        resid = np.linalg.norm(points - LensGrid(pitch, angle, offset, grid.lattice)
                               .lattice_xy(i, j), axis=1)
        use = resid <= max(4 * 1.4826 * float(np.median(resid)), 0.01 * grid.pitch_px)
        if use.sum() < FIELD_REGIONS:
            return None
    return pitch, angle, offset, se


MISFIT_REGIONS = 3     # round regions that measure a scale and a turn (6 values, 4 unknowns)
REGION_SCATTER = 0.01  # pitches: no region's centre is placed better than this


def regions_misfit(flat: np.ndarray, grid: LensGrid, tiles: int, measured: tuple | None = None
                   ) -> tuple[float, float] | None:
    """How far (px) the round mean micro-images of ``tiles`` x ``tiles`` regions
    (:func:`regional_shifts`) put the frame's corner lenses from where ``grid``'s pitch and
    rotation put them, and its standard error (px); None when fewer than MISFIT_REGIONS
    regions are round. Each region's shift from ``grid`` is fitted as a common shift plus a
    scale e and a turn d about the grid's offset lens; the corners then move by (|e| + |d|)
    x the half-diagonal, as a pitch and angle error move them (``_corner_error``). The
    standard error comes from the regions' scatter about that fit, at least REGION_SCATTER.
    ``measured``: the regions' (middles, shifts) when known."""
    middles, shifts = measured or regional_shifts(flat, grid, tiles=tiles)
    if len(shifts) < MISFIT_REGIONS:
        return None
    m = middles - np.asarray(grid.offset_xy)
    design = np.zeros((2 * len(m), 4))
    design[0::2, 0] = design[1::2, 1] = 1.0
    design[0::2, 2], design[1::2, 2] = m[:, 0], m[:, 1]      # scale
    design[0::2, 3], design[1::2, 3] = -m[:, 1], m[:, 0]     # turn
    values = shifts.reshape(-1)
    coef = np.linalg.lstsq(design, values, rcond=None)[0]
    scatter2 = max(float(np.sum((values - design @ coef) ** 2)) / (len(values) - 4),
                   (REGION_SCATTER * grid.pitch_px) ** 2)
    se = np.sqrt(np.diag(scatter2 * np.linalg.pinv(design.T @ design)))
    half_diagonal = float(np.hypot(*flat.shape)) / 2
    return (half_diagonal * (abs(coef[2]) + abs(coef[3])),
            half_diagonal * float(np.hypot(se[2], se[3])))


FIELD_REGIONS = 12     # regions (of 16) that must show a round mean micro-image
FIELD_AGREEMENT = 0.02  # robust scatter (pitches) of the regions about the field


def smooth_field(middles: np.ndarray, shifts: np.ndarray, at: np.ndarray,
                 shape: tuple[int, int], pitch_px: float) -> np.ndarray:
    """(K, 2) shifts at points ``at`` from a robust (Huber-weighted) polynomial fit of degree
    ``FIELD_DEGREE`` through regional shifts (T, 2) at ``middles``. Zero (the lattice as it
    is) unless at least ``FIELD_REGIONS`` regions were measured and they scatter about the
    field by at most ``FIELD_AGREEMENT`` pitch: the field corrects tenths of a pixel and is
    only used where the regions agree on it. A field that would move a lens by more than
    ``FIELD_MAX`` pitch is not a bend of the array but a disagreement with the border lattice
    (a micro-image shape that changes over the frame moves its symmetry centre): zero then."""
    rows, cols = shape
    if len(shifts) < FIELD_REGIONS:
        return np.zeros_like(at)

    def terms(xy):
        u, v = (xy[:, 0] - cols / 2) / (cols / 2), (xy[:, 1] - rows / 2) / (rows / 2)
        return np.stack([u ** a * v ** b for a in range(FIELD_DEGREE + 1)
                         for b in range(FIELD_DEGREE + 1 - a)], axis=1)

    design, weight = terms(middles), np.ones(len(shifts))
    for _ in range(10):
        w = np.sqrt(weight)[:, None]
        coef = np.linalg.lstsq(design * w, shifts * w, rcond=None)[0]
        resid = np.linalg.norm(shifts - design @ coef, axis=1)
        scale = 1.4826 * float(np.median(resid))
        weight = np.minimum(1.0, 2 * scale / np.maximum(resid, 1e-9))
    field = terms(at) @ coef
    if scale > FIELD_AGREEMENT * pitch_px or np.hypot(*field.T).max() > FIELD_MAX * pitch_px:
        return np.zeros_like(at)
    return field


def _robust_fit(idx, centres, refined, grid):
    """Least-squares lattice through the refined centres, dropping those beyond 4 robust
    sigma (at most four rounds); the grid re-indexed about the image centre, the lenses used
    and the standard errors."""
    use = refined.copy()
    for _ in range(4):
        pitch, angle, offset, se = fit_lattice(idx[use], centres[use], lattice=grid.lattice,
                                               return_se=True)
        fitted = LensGrid(pitch, angle, offset, grid.lattice)
        resid = np.linalg.norm(centres - fitted.lattice_xy(idx[:, 0], idx[:, 1]), axis=1)
        sigma = 1.4826 * np.median(resid[refined])
        new_use = refined & (resid <= max(4.0 * sigma, 0.02))
        if np.array_equal(new_use, use):
            break
        use = new_use
    return reindexed(pitch, angle, offset, grid.lattice, grid.image_shape), use, se


def _residual_rms(grid: LensGrid, idx, centres, use) -> float:
    i, j = grid.nearest_index(centres[use, 0], centres[use, 1])
    return float(np.sqrt(np.mean(np.sum((centres[use] - grid.lattice_xy(i, j)) ** 2, axis=1))))


def _on_grid(grid: LensGrid, idx, ideal, centres, use):
    """The measured centres placed on the lenses (idx) of ``grid`` (the ideal centre where a
    lens has none), and which lenses have one."""
    i, j = grid.nearest_index(centres[:, 0], centres[:, 1])
    i, j = i[use], j[use]
    lo = np.minimum(idx.min(axis=0), [i.min(initial=0), j.min(initial=0)])
    hi = np.maximum(idx.max(axis=0), [i.max(initial=0), j.max(initial=0)])
    source = np.full(tuple(hi - lo + 1), -1, np.int64)   # measured centre by lens index
    source[i - lo[0], j - lo[1]] = np.flatnonzero(use)
    src = source[idx[:, 0] - lo[0], idx[:, 1] - lo[1]]
    measured = src >= 0
    final = ideal.copy()
    final[measured] = centres[src[measured]]
    return final, measured
