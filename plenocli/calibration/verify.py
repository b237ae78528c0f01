"""Which hypothesis is the lens lattice, and how sure that is.

The measure: the autocorrelation A(t) of the border signal (gradient magnitude of the flattened
image) at long lags t. Two properties of every lenslet image make it decisive:

1. The micro-image borders (dark gaps, the vignetting edge of each micro-image) sit on the same
   lattice over the whole frame, so A has equal peaks at every lattice vector, as far as the
   frame reaches. Scene content does not: a scene point is repeated by the parallax in a few
   neighbouring micro-images only, at a depth-dependent period. Far lags keep the borders and
   drop the scene.
2. A lattice's relatives differ from it in a way A sees. Every point of the true lattice L is
   a peak; every hole of L (edge midpoints, the centres of its triangles or squares) is a
   trough. A coarser relative (x2, x sqrt(3)) has true lattice points among its holes; a finer
   one (/2, /sqrt(3)) has true holes among its points. So the *contrast*

       min over point classes of mean A  -  max over hole classes of mean A

   (point classes: the cosets of the index-4 and index-3 (hex) / index-2 (square)
   sub-lattices, so a finer relative cannot hide its false points in an average) is positive
   only for the true lattice and about zero or negative for every relative, the other lattice
   kind and a lattice detuned by a fraction of a pitch at the far lags.

It is normalised by the spread of A over the sampled lags, so it does not depend on brightness,
noise level or the image size. The winner must beat every unrelated hypothesis by a clear
factor (else the command names both and stops), and beat copies of itself detuned in pitch and
angle (else there is no lattice at all: a photo, noise, a flat field).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.fft
from scipy import ndimage
from scipy.optimize import minimize

from plenocli.calibration.candidates import Lattice

WIN_RATIO = 2.0        # the winner's contrast over any unrelated hypothesis
NULL_RATIO = 3.0       # the winner's contrast over its own detuned copies
MIN_CONTRAST = 0.15    # lattice points above holes by this share of the spread of A


class Autocorrelation:
    """A(t) of a border signal (a crop at one decimation ``factor``), normalised by the overlap
    of the shifted crop with itself (every lag is a mean, not a sum) and by A(0)."""

    def __init__(self, signal: np.ndarray, factor: int):
        rows, cols = signal.shape
        data = signal - np.float32(signal.mean())
        shape = (2 * rows, 2 * cols)   # zero padding: no wrap-around
        power = np.abs(scipy.fft.rfft2(data, s=shape, workers=-1)) ** 2
        acf = scipy.fft.irfft2(power, s=shape, workers=-1)
        ones = scipy.fft.rfft2(np.ones((rows, cols), np.float32), s=shape, workers=-1)
        overlap = scipy.fft.irfft2(np.abs(ones) ** 2, s=shape, workers=-1)
        acf = acf / np.maximum(overlap, 1.0)
        self.acf = np.fft.fftshift(acf / max(acf[0, 0], 1e-30)).astype(np.float32)
        self.factor = factor
        self.reach = 0.45 * min(rows, cols)   # lags beyond this overlap too little of the crop

    def contrast(self, lattice: Lattice, *, near: float = 3.0, far: float | None = None
                 ) -> float:
        """Contrast of ``lattice`` over lags from ``near`` pitches (or 15 % of the crop) to
        ``far`` pitches (default: as far as the crop reaches). See the module docstring."""
        basis = lattice.basis() / self.factor
        pitch = lattice.pitch_px / self.factor
        hi = self.reach if far is None else min(far * pitch, self.reach)
        lo = min(max(near * pitch, 0.15 * self.reach if far is None else 0.0), 0.8 * hi)
        if hi < 1.5 * pitch:
            return -np.inf
        n = int(hi / (pitch * np.sin(np.pi / 3))) + 2
        k, m = np.meshgrid(np.arange(-n, n + 1), np.arange(0, n + 1), indexing="ij")
        k, m = k.ravel(), m.ravel()
        pts = k[:, None] * basis[0] + m[:, None] * basis[1]
        dist = np.hypot(pts[:, 0], pts[:, 1])
        keep = (dist >= lo) & (dist <= hi)
        pts, k, m = pts[keep], k[keep], m[keep]
        if len(pts) < 12:
            return -np.inf
        b1, b2 = basis
        if lattice.kind == "hex":
            classes = [((k % 2 == a) & (m % 2 == b)) for a in (0, 1) for b in (0, 1)]
            classes += [((k - m) % 3 == a) for a in (0, 1, 2)]
            holes = [b1 / 2, b2 / 2, (b1 + b2) / 2, (b1 + b2) / 3, 2 * (b1 + b2) / 3]
        else:
            classes = [((k % 2 == a) & (m % 2 == b)) for a in (0, 1) for b in (0, 1)]
            classes += [((k + m) % 2 == a) for a in (0, 1)]
            holes = [b1 / 2, b2 / 2, (b1 + b2) / 2]
        at_points = self._sample(pts)
        at_holes = [self._sample(pts + h) for h in holes]
        point_means = [at_points[c].mean() for c in classes if c.any()]
        spread = float(np.std(np.concatenate([at_points, *at_holes])))
        if spread <= 0:
            return -np.inf
        return float(min(point_means) - max(h.mean() for h in at_holes)) / spread

    def _sample(self, lags: np.ndarray) -> np.ndarray:
        cy, cx = self.acf.shape[0] // 2, self.acf.shape[1] // 2
        return ndimage.map_coordinates(self.acf, [cy + lags[:, 1], cx + lags[:, 0]], order=1,
                                       mode="constant", cval=0.0)


@dataclass(frozen=True)
class Verdict:
    """The lattice chosen, its contrast, the best unrelated rivals and the detuned control."""

    lattice: Lattice
    contrast: float
    rivals: tuple[tuple[Lattice, float], ...] = field(default=())
    control: float = 0.0

    @property
    def margin(self) -> float:
        """Winner over the best rival (inf without one)."""
        best = max((c for _, c in self.rivals), default=0.0)
        return self.contrast / best if best > 0 else float("inf")

    def to_dict(self) -> dict:
        return {"contrast": round(self.contrast, 4), "control": round(self.control, 4),
                "margin": None if np.isinf(self.margin) else round(self.margin, 3),
                "rivals": [{"lattice": lat.kind, "pitch_px": round(lat.pitch_px, 4),
                            "angle_deg": round(float(np.degrees(lat.angle_rad)), 4),
                            "contrast": round(c, 4)} for lat, c in self.rivals]}


def refine(lattice: Lattice, acf: Autocorrelation) -> tuple[Lattice, float]:
    """Local maximum of the contrast around ``lattice``: Nelder-Mead in (log pitch, angle),
    first over near lags (a wide basin), then over all lags (a sharp one)."""
    current = lattice
    for near, far, span in ((1.5, 6.0, 0.01), (3.0, 14.0, 0.003), (None, None, 0.001)):
        def cost(p, base=current, near=near, far=far):
            cand = Lattice(base.kind, base.pitch_px * np.exp(p[0]), base.angle_rad + p[1])
            c = acf.contrast(cand) if near is None else acf.contrast(cand, near=near, far=far)
            return -c if np.isfinite(c) else 10.0

        res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                       options={"initial_simplex": [[0, 0], [span, 0], [0, span]],
                                "xatol": 1e-5, "fatol": 1e-4, "maxfev": 60})
        current = Lattice(current.kind, current.pitch_px * np.exp(res.x[0]),
                          current.angle_rad + res.x[1])
    return current, acf.contrast(current)


def control_contrast(lattice: Lattice, acf: Autocorrelation) -> float:
    """The best contrast of ``lattice`` detuned in pitch or angle so that its farthest sampled
    lag moves by half a pitch: a lattice that is not there, seen by the same measure."""
    pitch = lattice.pitch_px / acf.factor
    shift = 0.5 * pitch / max(acf.reach, 2 * pitch)
    copies = [lattice.scaled(1 + s) for s in (-shift, shift)]
    copies += [lattice.scaled(1.0, s) for s in (-shift, shift)]
    return max(0.0, *(acf.contrast(c) for c in copies))


def judge(scored: list[tuple[Lattice, float]], control: float) -> Verdict:
    """The winner of refined, scored hypotheses and its unrelated rivals (related = the same
    lattice found twice)."""
    ranked = sorted(scored, key=lambda t: -t[1])
    best, contrast = ranked[0]
    rivals: list[tuple[Lattice, float]] = []
    for lat, c in ranked[1:]:
        if lat.same_as(best) or any(lat.same_as(r) for r, _ in rivals):
            continue
        rivals.append((lat, c))
    return Verdict(best, contrast, tuple(rivals[:3]), control)


def doubt(verdict: Verdict) -> str | None:
    """Why the verdict cannot be vouched for, or None."""
    if verdict.contrast < MIN_CONTRAST or verdict.contrast < NULL_RATIO * verdict.control:
        return "no micro-lens lattice found (no hypothesis shows micro-image borders repeated " \
               "over the frame)"
    if verdict.margin < WIN_RATIO:
        rival, c = verdict.rivals[0]
        return (f"unsure lattice: {verdict.lattice.describe()} (contrast "
                f"{verdict.contrast:.2f}) or {rival.describe()} (contrast {c:.2f})")
    return None
