"""Which hypothesis is the lens lattice, and how sure that is.

The measure: the autocorrelation A(t) of the flattened image and of its border signal (gradient
magnitude) at long lags t; a lattice must pass on both. Two properties of every lenslet image
make it decisive:

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

import numba
import numpy as np
import scipy.fft

from plenocli.calibration.candidates import MIN_LENS_PITCH_PX, Lattice, _parabola

WIN_RATIO = 2.0        # the winner's contrast over any unrelated hypothesis
NULL_RATIO = 3.0       # the winner's contrast over its own detuned copies
MIN_CONTRAST = 0.15    # lattice points above holes by this share of the spread of A
MIN_LAGS = 12          # fewer lattice lags in the annulus: no contrast
HOLE_REACH = 1.2       # the farthest hole from its lattice point (2 |b1 + b2| / 3 = 1.155 pitches)


class Autocorrelation:
    """A(t) of the signals of one view (a crop at one decimation ``factor``): the flattened
    intensity (each micro-image bright inside, dark at its rim) and the border signal (its
    edges), each normalised by the overlap of the shifted crop with itself (every lag is a
    mean, not a sum) and by A(0). A lattice must show in both.

    Only the lags a measure can sample are computed and kept: out to the reach plus the
    farthest hole of ``widest_pitch`` (view px), the widest pitch this view judges (None: any
    pitch whose annulus fits the reach)."""

    def __init__(self, signals: tuple[np.ndarray, ...], factor: int,
                 widest_pitch: float | None = None):
        rows, cols = signals[0].shape
        self.factor = factor
        self.reach = 0.45 * min(rows, cols)   # lags beyond this overlap too little of the crop
        # only the lags a measure can sample are kept: the reach plus the farthest hole of the
        # widest pitch judged in this view (no annulus holds more than reach / 1.5)
        widest = self.reach / 1.5 if widest_pitch is None else widest_pitch
        extent = int(np.ceil(self.reach + HOLE_REACH * widest)) + 3
        ext_r, ext_c = min(extent, rows - 1), min(extent, cols - 1)
        # zero padding by the kept lags: no wrap-around reaches them
        shape = (scipy.fft.next_fast_len(rows + ext_r + 1, real=True),
                 scipy.fft.next_fast_len(cols + ext_c + 1, real=True))
        lag_r, lag_c = np.arange(-ext_r, ext_r + 1), np.arange(-ext_c, ext_c + 1)
        # pixels a shift (dy, dx) keeps inside the crop: every lag is a mean, not a sum
        overlap_r = (rows - np.abs(lag_r)).astype(np.float32)[:, None]
        overlap_c = (cols - np.abs(lag_c)).astype(np.float32)[None, :]
        self.stack = np.empty((len(signals), len(lag_r), len(lag_c)), np.float32)
        for acf, signal in zip(self.stack, signals, strict=True):
            _lags_of_autocorrelation(signal, shape, acf)
            acf /= overlap_r
            acf /= overlap_c
            acf /= max(float(acf[ext_r, ext_c]), 1e-30)
        self.acfs = list(self.stack)
        self.acf = self.acfs[-1]   # the border signal's: its peaks are the sharpest

    def contrast(self, lattice: Lattice, *, near: float = 3.0, far: float | None = None
                 ) -> float:
        """Contrast of ``lattice`` over lags from ``near`` pitches (or 15 % of the reach) to
        ``far`` pitches (default: as far as the crop reaches). See the module docstring."""
        annulus = self._annulus(lattice, near, far)
        if annulus is None:
            return -np.inf
        basis, lo, hi, n = annulus
        return float(_contrast(self.stack, basis, lo, hi, n, lattice.kind == "hex"))

    def between(self, coarse: Lattice, fine: Lattice) -> np.ndarray:
        """How much the points of ``fine`` that are not points of ``coarse`` (its sub-lattice)
        look like lattice points: about 1 when ``fine`` is the lens lattice (they are lenses),
        about 0 or below when ``coarse`` is (they are its holes). (mean A there - mean A at the
        holes of ``fine``) / (mean A at the shared points - the same), one per signal (the
        intensity sees a lens as bright and a hole as dark; the border signal sees both as
        edges, but a lens of another type of a multi-focus array as a lens)."""
        lags = self._lags(fine, 3.0, None)
        if lags is None:
            return np.full(len(self.acfs), np.nan)
        pts = lags[0]
        uv = pts @ np.linalg.inv(coarse.basis() / self.factor)
        shared = np.all(np.abs(uv - np.rint(uv)) < 0.05, axis=1)
        if shared.all() or not shared.any():
            return np.full(len(self.acfs), np.nan)
        b1, b2 = fine.basis() / self.factor
        holes = [b1 / 2, b2 / 2, (b1 + b2) / 2]
        shares = []
        for acf in self.acfs:
            base = float(np.mean([self._sample(pts + h, acf).mean() for h in holes]))
            at = self._sample(pts, acf)
            top = float(at[shared].mean()) - base
            shares.append((float(at[~shared].mean()) - base) / top if top > 0 else np.nan)
        return np.asarray(shares)

    def peak_lags(self, lattice: Lattice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sub-pixel positions (px of the full image) of the autocorrelation peaks at the far
        lattice lags (the outer half of the reach), with their indices (k, m) and heights:
        the borders repeat exactly there, the scene no longer does. Each peak is the centroid
        of A - (its local floor) within a quarter pitch of the predicted lag."""
        lags = self._lags(lattice, 0.0, None)
        if lags is None:
            return np.empty((0, 2)), np.empty((0, 2), np.int64), np.empty(0)
        pts, k, m = lags
        far = np.hypot(pts[:, 0], pts[:, 1]) >= 0.5 * self.reach
        pts, k, m = pts[far], k[far], m[far]
        radius = max(1.5, 0.25 * lattice.pitch_px / self.factor)
        step = np.arange(-np.ceil(radius), np.ceil(radius) + 1)
        dx, dy = np.meshgrid(step, step)
        inside = np.hypot(dx, dy) <= radius
        dx, dy = dx[inside], dy[inside]
        cy, cx = self.acf.shape[0] // 2, self.acf.shape[1] // 2
        acf = self.acf
        r, c, height = _window_peaks(acf, cy + np.rint(pts[:, 1]).astype(np.int64),
                                     cx + np.rint(pts[:, 0]).astype(np.int64),
                                     dy.astype(np.int64), dx.astype(np.int64))
        found = np.stack([c - cx + _parabola(acf[r, c - 1], acf[r, c], acf[r, c + 1]),
                          r - cy + _parabola(acf[r - 1, c], acf[r, c], acf[r + 1, c])], axis=1)
        return found * self.factor, np.stack([k, m], axis=1), height

    def _annulus(self, lattice: Lattice, near: float, far: float | None):
        """Basis (view px), lag bounds lo, hi and index range n of the lag annulus, or None
        when it holds less than 1.5 pitches."""
        basis = lattice.basis() / self.factor
        pitch = lattice.pitch_px / self.factor
        hi = self.reach if far is None else min(far * pitch, self.reach)
        lo = min(max(near * pitch, 0.15 * self.reach if far is None else 0.0), 0.8 * hi)
        if hi < 1.5 * pitch:
            return None
        return basis, lo, hi, int(hi / (pitch * np.sin(np.pi / 3))) + 2

    def _lags(self, lattice: Lattice, near: float, far: float | None):
        """Lattice vectors (view px) of half the plane in the lag annulus, with indices."""
        annulus = self._annulus(lattice, near, far)
        if annulus is None:
            return None
        pts, k, m = _annulus_lags(*annulus)
        if len(pts) < MIN_LAGS:
            return None
        return pts, k, m

    @staticmethod
    def _sample(lags: np.ndarray, a: np.ndarray) -> np.ndarray:
        """``a`` (an autocorrelation) at lags (K, 2) (x, y) px of the view, bilinear."""
        return _bilinear(a, np.ascontiguousarray(lags, np.float64))


def _lags_of_autocorrelation(signal: np.ndarray, shape: tuple[int, int], out: np.ndarray
                             ) -> None:
    """The autocorrelation (sums) of ``signal`` minus its mean at lags -ext .. ext (``out``
    of (2 ext_r + 1, 2 ext_c + 1)), by FFTs zero-padded to ``shape``. The transforms go one
    axis at a time: the padding rows are never transformed, and of the inverse only the rows
    of the kept lags."""
    ext_r, ext_c = out.shape[0] // 2, out.shape[1] // 2
    centred = signal - np.float32(signal.mean())
    spectrum = scipy.fft.rfft(centred, n=shape[1], axis=1, workers=1)
    del centred
    spectrum = scipy.fft.fft(spectrum, n=shape[0], axis=0, workers=1, overwrite_x=True)
    power, imag = spectrum.real, spectrum.imag   # |F|^2 in place: no temporaries
    power *= power
    imag *= imag
    power += imag
    imag[...] = 0.0
    spectrum = scipy.fft.ifft(spectrum, axis=0, workers=1, overwrite_x=True)
    # lags -ext .. ext: the wrapped-around tail, then the head
    kept = np.concatenate([spectrum[shape[0] - ext_r:], spectrum[:ext_r + 1]])
    del spectrum, power, imag
    wrapped = scipy.fft.irfft(kept, n=shape[1], axis=1, workers=1)
    del kept
    out[:, :ext_c] = wrapped[:, shape[1] - ext_c:]
    out[:, ext_c:] = wrapped[:, :ext_c + 1]


@numba.njit(cache=True, nogil=True)
def _annulus_lags(basis, lo, hi, n):  # pragma: no cover - compiled
    """The lattice vectors k b1 + m b2 (-n <= k <= n, 0 <= m <= n, in that order) with
    lo <= |lag| <= hi, and their k and m (numba kernel: a peak search asks for them at every
    step)."""
    size = (2 * n + 1) * (n + 1)
    pts = np.empty((size, 2))
    ks, ms = np.empty(size, np.int64), np.empty(size, np.int64)
    kept = 0
    for k in range(-n, n + 1):
        for m in range(0, n + 1):
            x = k * basis[0, 0] + m * basis[1, 0]
            y = k * basis[0, 1] + m * basis[1, 1]
            dist = np.hypot(x, y)
            if dist >= lo and dist <= hi:
                pts[kept, 0], pts[kept, 1], ks[kept], ms[kept] = x, y, k, m
                kept += 1
    return pts[:kept].copy(), ks[:kept].copy(), ms[:kept].copy()


@numba.njit(cache=True, nogil=True)
def _bilinear(a, lags):  # pragma: no cover - compiled
    """``a`` at (K, 2) lags (x, y) from its centre, bilinear, clamped to the array (numba
    kernel: no (K,) temporaries per step)."""
    out = np.empty(lags.shape[0])
    for i in range(lags.shape[0]):
        out[i] = _bilinear_at(a, lags[i, 0], lags[i, 1])
    return out


@numba.njit(cache=True, nogil=True)
def _bilinear_at(a, dx, dy):  # pragma: no cover - compiled
    """``a`` at (dx, dy) from its centre, bilinear, clamped to the array: the one sampling
    of the autocorrelation the kernels share."""
    rows, cols = a.shape
    x = dx + cols // 2
    y = dy + rows // 2
    x0 = min(max(int(np.floor(x)), 0), cols - 2)
    y0 = min(max(int(np.floor(y)), 0), rows - 2)
    fx = min(max(x - x0, 0.0), 1.0)
    fy = min(max(y - y0, 0.0), 1.0)
    top = a[y0, x0] * (1 - fx) + a[y0, x0 + 1] * fx
    bottom = a[y0 + 1, x0] * (1 - fx) + a[y0 + 1, x0 + 1] * fx
    return top * (1 - fy) + bottom * fy


@numba.njit(cache=True, nogil=True)
def _hole_offsets(basis, hexagonal):  # pragma: no cover - compiled
    """The lattice point (0, 0) and its holes: the edge midpoints b1 / 2, b2 / 2,
    (b1 + b2) / 2 and, hex, the triangle centres (b1 + b2) / 3, 2 (b1 + b2) / 3."""
    out = np.zeros((6 if hexagonal else 4, 2))
    for d in range(2):
        b1, b2 = basis[0, d], basis[1, d]
        out[1, d], out[2, d], out[3, d] = b1 / 2, b2 / 2, (b1 + b2) / 2
        if hexagonal:
            out[4, d], out[5, d] = (b1 + b2) / 3, 2 * (b1 + b2) / 3
    return out


@numba.njit(cache=True, nogil=True)
def _contrast(acfs, basis, lo, hi, n, hexagonal):  # noqa: C901 # pragma: no cover
    """``Autocorrelation.contrast`` (numba kernel: a search evaluates it hundreds of times).
    The lattice lags k b1 + m b2 (m >= 0) with lo <= |lag| <= hi; each signal's A sampled
    bilinearly at every lag plus every offset (``_hole_offsets``: the lattice point, then its
    holes); point classes by (k mod 2, m mod 2) and by (k - m) mod 3 (hex) or (k + m) mod 2
    (square). The minimum over the signals; -inf for fewer than MIN_LAGS lags or a signal
    without spread."""
    offsets = _hole_offsets(basis, hexagonal)
    lags, ks, ms = _annulus_lags(basis, lo, hi, n)
    kept = lags.shape[0]
    lag_x, lag_y = lags[:, 0], lags[:, 1]
    coset_a, coset_b = np.empty(kept, np.int64), np.empty(kept, np.int64)
    for i in range(kept):
        k, m = ks[i], ms[i]
        coset_a[i] = 2 * (k % 2) + m % 2
        coset_b[i] = 4 + ((k - m) % 3 if hexagonal else (k + m) % 2)
    if kept < MIN_LAGS:
        return -np.inf
    n_sig = acfs.shape[0]
    n_off = offsets.shape[0]
    values = np.empty((n_off, kept))
    worst = np.inf
    for s in range(n_sig):
        a = acfs[s]
        total = 0.0
        for o in range(n_off):
            for i in range(kept):
                values[o, i] = _bilinear_at(a, lag_x[i] + offsets[o, 0],
                                            lag_y[i] + offsets[o, 1])
                total += values[o, i]
        mean = total / (n_off * kept)
        var = 0.0
        for o in range(n_off):
            for i in range(kept):
                var += (values[o, i] - mean) ** 2
        spread = np.sqrt(var / (n_off * kept))
        if not spread > 0:
            return -np.inf
        sums, counts = np.zeros(7), np.zeros(7)
        for i in range(kept):
            for c in (coset_a[i], coset_b[i]):
                sums[c] += values[0, i]
                counts[c] += 1
        lowest_point = np.inf
        for c in range(7):
            if counts[c] > 0:
                lowest_point = min(lowest_point, sums[c] / counts[c])
        highest_hole = -np.inf
        for o in range(1, n_off):
            highest_hole = max(highest_hole, values[o].mean())
        worst = min(worst, (lowest_point - highest_hole) / spread)
    return worst


@numba.njit(cache=True, nogil=True)
def _window_peaks(acf, rows, cols, dy, dx):  # pragma: no cover - compiled
    """For each window centred at (rows[i], cols[i]) with offsets (dy, dx): the row and column
    of its maximum (the first one) and the maximum's height above the window's median
    (numba kernel: no (lags x window) temporaries)."""
    count = rows.shape[0]
    top_r, top_c = np.empty(count, np.int64), np.empty(count, np.int64)
    height = np.empty(count, acf.dtype)
    values = np.empty(dy.shape[0], acf.dtype)
    for i in range(count):
        best = -np.inf
        for w in range(dy.shape[0]):
            values[w] = acf[rows[i] + dy[w], cols[i] + dx[w]]
            if values[w] > best:
                best = values[w]
                top_r[i], top_c[i] = rows[i] + dy[w], cols[i] + dx[w]
        height[i] = max(best - np.median(values), 0.0)
    return top_r, top_c, height


@dataclass(frozen=True)
class Verdict:
    """The lattice chosen, its contrast, the best unrelated rivals and the detuned control."""

    lattice: Lattice
    contrast: float
    rivals: tuple[tuple[Lattice, float], ...] = field(default=())
    control: float = 0.0
    undecided: bool = False    # a sub- or super-lattice could not be ruled out
    # every refined hypothesis with its contrast (what a second judge or a hint looks at)
    considered: tuple[tuple[Lattice, float], ...] = field(default=(), compare=False, repr=False)

    @property
    def margin(self) -> float:
        """Winner over the best rival (inf without one)."""
        best = max((c for _, c in self.rivals), default=0.0)
        return self.contrast / best if best > 0 else float("inf")

    def to_dict(self) -> dict:
        return {"contrast": round(self.contrast, 4), "control": round(self.control, 4),
                "relative_undecided": self.undecided,
                "margin": None if np.isinf(self.margin) else round(self.margin, 3),
                "rivals": [{"lattice": lat.kind, "pitch_px": round(lat.pitch_px, 4),
                            "angle_deg": round(float(np.degrees(lat.angle_rad)), 4),
                            "contrast": round(c, 4)} for lat, c in self.rivals]}


REFINE_STAGES = ((1.5, 6.0, 0.01, 20), (3.0, 14.0, 0.003, 20), (None, None, 0.001, 30))


def refine(lattice: Lattice, acf: Autocorrelation) -> tuple[Lattice, float]:
    """Local maximum of the contrast around ``lattice``: Nelder-Mead in (log pitch, angle),
    first over near lags (a wide basin), then over all lags (a sharp one); REFINE_STAGES:
    (near, far pitches, first step, evaluations)."""
    current = lattice
    for near, far, span, evaluations in REFINE_STAGES:
        def score(lat, near=near, far=far):
            c = acf.contrast(lat) if near is None else acf.contrast(lat, near=near, far=far)
            return c if np.isfinite(c) else -10.0

        current = current.climbed(score, step=span, evaluations=evaluations, xatol=1e-5,
                                  fatol=1e-4)
    return current, acf.contrast(current)


def control_contrast(lattice: Lattice, acf: Autocorrelation) -> float:
    """The best contrast of ``lattice`` detuned in pitch or angle so that its farthest sampled
    lag moves by half a pitch: a lattice that is not there, seen by the same measure."""
    pitch = lattice.pitch_px / acf.factor
    shift = 0.5 * pitch / max(acf.reach, 2 * pitch)
    copies = [lattice.scaled(1 + s) for s in (-shift, shift)]
    copies += [lattice.scaled(1.0, s) for s in (-shift, shift)]
    return max(0.0, *(acf.contrast(c) for c in copies))


def settle(coarse: Lattice, fine: Lattice, acf: Autocorrelation) -> Lattice | None:
    """Which of a lattice and its sub-lattice is the lens lattice, by ``between`` on each
    signal: the fine one when their mean share is above 2/3 and none is below 1/3, the
    coarse one when the mean is below 1/3 and none is above 2/3, else None (a scene periodic
    on a relative of the lattice can make the signals disagree: then nobody can tell)."""
    shares = acf.between(coarse, fine)
    if not np.all(np.isfinite(shares)):
        return None
    mean = float(np.mean(shares))
    if mean > 2 / 3 and min(shares) > 1 / 3:
        return fine
    if mean < 1 / 3 and max(shares) < 2 / 3:
        return coarse
    return None


def nested(best: Lattice, other: Lattice) -> tuple[Lattice, Lattice] | None:
    """(coarse, fine) when one lattice is (nearly) a sub-lattice of the other, of any index,
    with ``other`` replaced by the exact lattice that ``best`` implies; else None."""
    if other.kind != best.kind:
        return None
    for coarse_is_best in (False, True):
        big, small = (best, other) if coarse_is_best else (other, best)
        ratio = big.basis() @ np.linalg.inv(small.basis())
        whole = np.rint(ratio)
        if np.abs(ratio - whole).max() > 0.05 or abs(round(np.linalg.det(whole))) < 2:
            continue
        if coarse_is_best:     # other is finer: its basis from best's
            vec = (np.linalg.inv(whole) @ best.basis())[0]
            exact = Lattice(best.kind, float(np.hypot(*vec)), float(np.arctan2(vec[1], vec[0])))
            return best, exact
        vec = (whole @ best.basis())[0]
        return Lattice(best.kind, float(np.hypot(*vec)), float(np.arctan2(vec[1], vec[0]))), best
    return None


def judge(scored: list[tuple[Lattice, float]], acf_for,
          leader: tuple[Lattice, float] | None = None) -> Verdict:
    """The winner of refined, scored hypotheses, checked against every hypothesis nested with
    it (a sub- or super-lattice of any index, and always its x2, /2, x sqrt(3) (sqrt(2))
    relatives) with ``settle`` rather than by contrast, and its unrelated rivals. ``leader``
    starts the checks instead of the highest contrast (a winner measured again)."""
    ranked = [t for t in sorted(scored, key=lambda t: -t[1]) if np.isfinite(t[1])]
    if leader is not None:
        ranked = [leader, *(t for t in ranked if not t[0].same_as(leader[0]))]
    if not ranked:
        return Verdict(scored[0][0], -np.inf)
    best, contrast = ranked[0]
    undecided: list[tuple[Lattice, float]] = []
    for _ in range(4):
        moved, undecided = False, []
        others = [*(lat for lat in best.relatives() if lat.kind == best.kind),
                  *(lat for lat, _ in ranked[1:])]
        for lat in others:
            pair = None if lat.same_as(best) else nested(best, lat)
            if pair is None or min(pair[1].pitch_px, lat.pitch_px) < MIN_LENS_PITCH_PX:
                continue
            other = pair[0] if pair[1] is best else pair[1]
            if any(other.same_as(u) for u, _ in undecided):
                continue
            truth = settle(*pair, acf_for(pair[1]))
            if truth is None:
                undecided.append((other, acf_for(other).contrast(other)))
            elif truth is other:
                best, contrast, moved = other, acf_for(other).contrast(other), True
                break
        if not moved:
            break
    rivals: list[tuple[Lattice, float]] = []
    for lat, c in ranked[1:]:
        if nested(best, lat) is None and not lat.same_as(best) and \
                not any(lat.same_as(r) for r, _ in rivals):
            rivals.append((lat, c))
    return Verdict(best, contrast, tuple(undecided + rivals)[:3], 0.0,
                   undecided=bool(undecided))


def doubt(verdict: Verdict) -> str | None:
    """Why the verdict cannot be vouched for, or None."""
    if verdict.contrast < MIN_CONTRAST or verdict.contrast < NULL_RATIO * verdict.control:
        return "no micro-lens lattice found (no hypothesis shows micro-image borders repeated " \
               "over the frame)"
    if verdict.undecided and not verdict.rivals:   # see search.judged
        return (f"unsure lattice: {verdict.lattice.describe()} (contrast "
                f"{verdict.contrast:.2f}) does not hold still when measured again")
    if verdict.undecided or verdict.margin < WIN_RATIO:
        rival, c = verdict.rivals[0]
        return (f"unsure lattice: {verdict.lattice.describe()} (contrast "
                f"{verdict.contrast:.2f}) or {rival.describe()} (contrast {c:.2f})")
    return None
