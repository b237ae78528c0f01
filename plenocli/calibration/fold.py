"""The second judge: what folding the frame onto a lattice does to it.

Every pixel is folded into one lattice cell by its fractional lattice coordinates (the frame's
mean micro-image, as in :func:`plenocli.calibration.centres.lens_centre`). Only the lens lattice
keeps the micro-images' shape (vignetting, aperture edge, the dark gaps or bright overlaps)
in register over the whole frame, so only its fold is sharp:

- a lattice off in pitch or angle, so that the frame's corners move by half a pitch, averages
  each bin over the micro-image and the gap: its fold is flat (the *control*);
- a finer relative (/2, /sqrt(3), /sqrt(2)) averages lens centres with holes;
- a coarser relative (x2, x sqrt(3)) folds as sharply, but its cell repeats itself: shifted to
  one of the cosets of its sub-lattice it matches itself (``self_match``), where the lens
  lattice's cell, shifted onto its holes or edge midpoints, does not;
- scene content (depth-dependent parallax repeats) does not fold: it averages out over
  thousands of micro-images.

The measure uses every pixel of the central frame (up to 2048 px a side, all lags at once),
unlike the border autocorrelation of the first judge, which samples a 1024-px crop at far lags;
a compressed or blurred frame whose borders no longer repeat sharply enough there still folds
into a clear mean micro-image.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np

from plenocli.calibration.candidates import Lattice
from plenocli.calibration.flatten import flatten

FOLD_PX = 2048          # side of the central region folded (full-image px)
SAMPLES = 262144        # pixels of the region folded (a seeded random choice: every phase of
#                         any lattice is covered, and every lattice sees the same pixels)
BINS = 12               # bins per lattice direction (a multiple of 6: holes fall on bins)
NULL_RATIO = 3.0        # sharpness over the detuned control
WIN_RATIO = 2.0         # sharpness over any unrelated lattice
COARSE_MATCH = 1 / 3    # a cell matching itself below this on a coset has holes there
NOISE_FLOOR = 10.0      # sharpness over what a fold of pure noise gives (bins^2 / samples)


@dataclass(frozen=True)
class FoldVerdict:
    """The lattice the fold judge confirms (None: it confirms none), with its sharpness (share
    of the image variance that is periodic on it), its detuned control, the best unrelated
    rivals and why it refuses."""

    lattice: Lattice | None
    sharpness: float
    control: float = 0.0
    rivals: tuple[tuple[Lattice, float], ...] = field(default=())
    reason: str | None = None

    def to_dict(self) -> dict:
        return {"sharpness": round(self.sharpness, 5), "control": round(self.control, 5),

                "refused": self.reason,
                "rivals": [{"lattice": lat.kind, "pitch_px": round(lat.pitch_px, 4),
                            "angle_deg": round(float(np.degrees(lat.angle_rad)), 4),
                            "sharpness": round(s, 5)} for lat, s in self.rivals]}


class Folds:
    """A seeded random sample of the pixels of the image's central region (flattened at the
    scale of ``pitch_px``), sorted by distance from the middle so that a central crop is a
    prefix; every lattice is folded from the same pixels."""

    def __init__(self, image: np.ndarray, pitch_px: float):
        rows, cols = image.shape
        side_r, side_c = min(rows, FOLD_PX), min(cols, FOLD_PX)
        r0, c0 = (rows - side_r) // 2, (cols - side_c) // 2
        self._sample(flatten(image[r0:r0 + side_r, c0:c0 + side_c],
                             scale_px=max(2 * pitch_px, 16.0)), 1)

    @classmethod
    def of_view(cls, flat: np.ndarray, factor: int) -> Folds:
        """A quarter as many samples of a view's flattened crop (decimated by ``factor``), in
        full-image px, not sorted: enough to tell a lattice from its relatives, not to refine
        it (no crops)."""
        out = object.__new__(cls)
        out._sample(flat, factor, count=SAMPLES // 4, by_distance=False)
        return out

    def _sample(self, flat: np.ndarray, factor: int, *, count: int = SAMPLES,
                by_distance: bool = True) -> None:
        side_r, side_c = flat.shape
        pick = np.random.default_rng(0).integers(0, flat.size, size=min(count, flat.size))
        y, x = np.divmod(pick, side_c)
        x = (x - (side_c - 1) / 2) * factor
        y = (y - (side_r - 1) / 2) * factor
        order = np.argsort(np.hypot(x, y), kind="stable") if by_distance else \
            np.arange(len(pick))
        self.x, self.y = x[order].astype(np.float64), y[order].astype(np.float64)
        self.values = flat.ravel()[pick][order].astype(np.float64)
        self.distance = np.hypot(self.x, self.y)
        centred = self.values - self.values.mean()   # running sums of the centred values
        self.sums = np.concatenate([[0.0], np.cumsum(centred)])
        self.squares = np.concatenate([[0.0], np.cumsum(centred * centred)])
        self.radius = float(np.hypot(side_r, side_c)) * factor / 2

    def _count(self, crop: float) -> int:
        if crop >= 1.0:
            return len(self.values)
        return int(np.searchsorted(self.distance, crop * self.radius))

    def cell(self, lattice: Lattice, crop: float = 1.0) -> tuple[np.ndarray, float]:
        """The folded cell (BINS x BINS, lattice (0, 0) at the region's middle) of the samples
        within ``crop`` of the region's half-diagonal, and its sharpness (variance of the cell
        over the variance of the samples)."""
        count = self._count(crop)
        inv = np.linalg.inv(lattice.basis().T)
        cell = _fold_samples(self.x[:count], self.y[:count], self.values[:count], inv, BINS)
        if count < 2 or np.isnan(cell).mean() > 0.1:
            return cell, 0.0
        mean = self.sums[count] / count   # the samples' variance from running sums
        spread = self.squares[count] / count - mean * mean
        return cell, float(np.nanvar(cell)) / spread if spread > 0 else 0.0

    def sharpness(self, lattice: Lattice, crop: float = 1.0) -> float:
        return self.cell(lattice, crop)[1]

    def noise_floor(self) -> float:
        return NOISE_FLOOR * BINS * BINS / len(self.values)


@numba.njit(cache=True, nogil=True)
def _fold_samples(x, y, values, inv, bins):  # pragma: no cover - compiled
    """Mean of ``values`` per bin of fractional lattice coordinates (``inv``: the inverse of
    the basis as columns), NaN where none fell (numba kernel: serial, a judge folds many
    lattices of a few hundred thousand samples)."""
    total = np.zeros(bins * bins)
    count = np.zeros(bins * bins)
    a00, a01, a10, a11 = inv[0, 0], inv[0, 1], inv[1, 0], inv[1, 1]
    for k in range(x.shape[0]):
        a = a00 * x[k] + a01 * y[k]
        b = a10 * x[k] + a11 * y[k]
        u = min(int((a - np.floor(a)) * bins), bins - 1)
        v = min(int((b - np.floor(b)) * bins), bins - 1)
        total[u * bins + v] += values[k]
        count[u * bins + v] += 1.0
    out = np.full(bins * bins, np.nan)
    for b in range(bins * bins):
        if count[b] > 0:
            out[b] = total[b] / count[b]
    return out.reshape(bins, bins)


# (radius in pitches, first step in pitches at that radius, evaluations)
REFINE_STAGES = ((8.0, 0.25, 20), (20.0, 0.1, 15), (None, 0.05, 20))


def refine_fold(lattice: Lattice, folds: Folds) -> tuple[Lattice, float]:
    """The local maximum of the fold's sharpness near ``lattice``: Nelder-Mead in (log pitch,
    angle) over the central 8 pitches (a wide basin), then 20, then the whole region (a
    sharp one)."""
    current = lattice
    for reach, step, evaluations in REFINE_STAGES:
        crop = 1.0 if reach is None else min(1.0, reach * current.pitch_px / folds.radius)
        span = step * current.pitch_px / (crop * folds.radius)

        current = current.climbed(lambda lat, crop=crop: folds.sharpness(lat, crop),
                                  step=span, evaluations=evaluations, xatol=1e-6, fatol=1e-7)
    return current, folds.sharpness(current)


def fold_control(lattice: Lattice, folds: Folds) -> float:
    """The best sharpness of ``lattice`` detuned in pitch or angle so that the region's
    corners move by half a pitch: a lattice that is not there, seen by the same measure."""
    shift = 0.5 * lattice.pitch_px / folds.radius
    copies = [lattice.scaled(1 + s) for s in (-shift, shift)]
    copies += [lattice.scaled(1.0, s) for s in (-shift, shift)]
    return max(folds.sharpness(c) for c in copies)


def _cosets(kind: str, index: int) -> list[tuple[int, int]]:
    """Cell positions (bins) of the extra lenses of a lattice whose index-``index``
    sub-lattice is the folded one: index 4 (x2), index 3 (hex x sqrt(3)), index 2 (square
    x sqrt(2))."""
    n = BINS
    return {4: [(n // 2, 0), (0, n // 2), (n // 2, n // 2)],
            3: [(n // 3, n // 3), (2 * n // 3, 2 * n // 3)], 2: [(n // 2, n // 2)]}[index]


def nested_pairs(lattice: Lattice) -> list[tuple[Lattice, Lattice, int]]:
    """(coarse, fine, index) for the lattice and each of its nearest finer and coarser
    relatives."""
    root, turn, index = (np.sqrt(3), np.pi / 6, 3) if lattice.kind == "hex" else \
        (np.sqrt(2), np.pi / 4, 2)
    return [(lattice, lattice.scaled(0.5), 4), (lattice, lattice.scaled(1 / root, turn), index),
            (lattice.scaled(2), lattice, 4), (lattice.scaled(root, turn), lattice, index)]


def coset_match(cell: np.ndarray, shifts: list[tuple[int, int]]) -> np.ndarray:
    """Normalised correlation of a folded cell with itself shifted by each of ``shifts``
    (bins): about 1 where the shift lands on another lens (the cell holds several), low or
    negative where it lands on holes or edge midpoints."""
    centred = np.nan_to_num(cell - np.nanmean(cell))
    norm = float(np.sum(centred * centred))
    if not norm > 0:
        return np.zeros(len(shifts))
    return np.array([float(np.sum(centred * np.roll(centred, s, axis=(0, 1)))) / norm
                     for s in shifts])


def settle_fold(coarse: Lattice, fine: Lattice, index: int, folds: Folds) -> Lattice | None:
    """Which of a lattice and its sub-lattice is the lens lattice: the fine one when the
    coarse cell matches itself on every coset the fine one adds (> 1/2: lenses there), the
    coarse one when it matches itself on none (< 1/3: holes there), else None."""
    match = coset_match(folds.cell(coarse)[0], _cosets(coarse.kind, index))
    if match.min() > 1 / 2:
        return fine
    if match.max() < COARSE_MATCH:
        return coarse
    return None


def fold_judge(candidates: list[Lattice], folds: Folds) -> FoldVerdict:
    """The fold judge's verdict on candidate lattices: each refined to its sharpest fold, the
    sharpest moved through its nested relatives by :func:`settle_fold`, then checked against
    its detuned control, the noise floor and every unrelated candidate."""
    from plenocli.calibration.verify import nested

    refined: list[tuple[Lattice, float]] = []
    for lat in candidates:
        if not any(lat.same_as(r, rel=0.003, angle=0.003) for r, _ in refined):
            refined.append(refine_fold(lat, folds))
    if not refined:
        return FoldVerdict(None, 0.0, reason="no lattice to fold")
    best, sharp = max(refined, key=lambda t: t[1])
    for _ in range(4):
        moved = False
        for coarse, fine, index in nested_pairs(best):
            truth = settle_fold(coarse, fine, index, folds)
            if truth is None:
                return FoldVerdict(None, sharp, reason=(
                    f"the fold cannot tell {coarse.describe()} from {fine.describe()}"))
            if truth is not best:
                best, sharp = refine_fold(truth, folds)
                moved = True
                break
        if not moved:
            break
    control = fold_control(best, folds)
    rivals = sorted(((lat, s) for lat, s in refined
                     if not lat.same_as(best, rel=0.01, angle=0.01) and nested(best, lat) is None),
                    key=lambda t: -t[1])[:3]
    verdict = FoldVerdict(best, sharp, control, tuple(rivals))
    reason = None
    if sharp < folds.noise_floor() or sharp < NULL_RATIO * control:
        reason = (f"the fold on {best.describe()} is not sharp (sharpness {sharp:.4f}, "
                  f"detuned {control:.4f})")
    elif rivals and sharp < WIN_RATIO * rivals[0][1]:
        reason = (f"the folds on {best.describe()} ({sharp:.4f}) and "
                  f"{rivals[0][0].describe()} ({rivals[0][1]:.4f}) are alike")
    return verdict if reason is None else FoldVerdict(None, sharp, control, tuple(rivals),
                                                      reason=reason)
