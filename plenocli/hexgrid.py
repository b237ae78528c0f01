"""Micro-lens grid calibration from a white (or scene) image with the Fourier transform.

Method (paper section 5.2, made precise):

1. **Flatten.** Each CFA plane (or the mono image) is divided by a heavily blurred copy of itself
   (Gaussian, ~64 px): main-lens vignetting and colour balance go, the micro-lens pattern stays.
   Hot pixels are clipped.
2. **Find the reciprocal lattice.** The Hann-windowed FFT of a central crop shows the lattice as
   peaks. Their log-magnitude is turned into a z-score against the radial mean (1/f scene
   spectra, noise). Each strong peak is a hypothesis for a fundamental; a hypothesis is scored on
   the whole hexagonal (or square) pattern it predicts (first three rings), so a single false
   periodicity from repeated scene content cannot win; then finer lattices are tried (a
   hypothesis that only saw a harmonic is replaced by the lattice whose extra peaks are present).
   2b. When the spectrum is not decisive (scene images, small crops: the parallax repeats scene
   content with periods that outscore the lattice), hypotheses from several windows and from
   the gradient-magnitude spectrum are scored by how sharply the micro-image borders fold onto
   one lattice cell (independent of the scene), refined, and walked in scale; see
   ``_lattice_by_fold`` and docs/calibrate.md.
3. **Sub-bin lattice.** Every harmonic with a clear peak is located with a parabolic fit; the
   reciprocal basis is the least-squares fit of all of them; the offset comes from the phases of
   the fundamentals (direct DFT at the fitted frequencies).
4. **Per-lens centres.** Each micro-image centre is its point-symmetry centre: Gauss-Newton on
   sum w (I(x) - I(2c - x))^2 over a disc of 0.6 pitch (edges carry the position; a centroid
   only sees the flat top).
5. **Lattice fit.** A hexagonal (square) similarity lattice ``x_ij = o + i b1 + j b2``,
   ``b2 = R(60 deg) b1`` is linear in (o, b1): robust least squares over all lens centres gives
   pitch, rotation and offset; the residuals (centre - lattice) are the report.

Coordinates: x = column, y = row (down), pixel centres at integers; see ``plenocli.model.lensgrid``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np
import scipy.fft

from plenocli.errors import CalibrationError
from plenocli.model.lensgrid import LATTICES, LensGrid

PITCH_RANGE_PX = (5.0, 80.0)   # search range; the documented working range is 6-60 px
MIN_SIDE_PX = 48               # smaller images cannot hold a lattice worth fitting
MIN_LENSES = 12                # fewer refined lenses: no reliable lattice fit
FFT_CROP_PX = 1024             # the coarse search works on a central crop of at most this size
SCENE_RESIDUAL = 0.04   # per-lens residual RMS (in pitches) above which centres are not kept
PEAK_Z = 4.0                   # a spectral peak must stand this many sigma above its ring
FLAT_SCALE = 1.5               # blur before refinement (pitches)
EDGE_MARGIN = 0.25             # border (pitches, beyond the disc) where lenses keep the lattice


@dataclass(frozen=True)
class CalibrationReport:
    """How well the per-lens centres fit the lattice (pixels)."""

    lenses_total: int
    lenses_refined: int
    outliers: int
    residual_rms_px: float
    residual_max_px: float
    spectrum_score: float      # spectral lattice score, or the border-fold contrast (scenes)
    centres_refined: bool = True   # False: a scene image, the centres are the lattice's

    def to_dict(self) -> dict:
        return {k: (v if isinstance(v, bool) else float(v) if isinstance(v, float) else int(v))
                for k, v in self.__dict__.items()}


# ----------------------------------------------------------------------------------------------
# 1. flatten
def flatten(image: np.ndarray, *, cfa: str | None = None, scale_px: float = 64.0) -> np.ndarray:
    """Divide each CFA plane by its blurred self: vignetting, colour balance and scene
    brightness go, the micro-lens pattern (periods < ``scale_px``) stays.

    Parameters
    ----------
    image : (rows, cols) array, any real dtype
    cfa : 2 x 2 Bayer pattern at pixel (0, 0), or None for mono / one colour plane
    scale_px : Gaussian sigma of the blur, in pixels of ``image``

    Returns
    -------
    (rows, cols) float32, about 1 on average, clipped to [0, 4].
    """
    if image.ndim != 2:
        raise ValueError(f"image must be 2-D, got shape {image.shape}")
    step = 2 if cfa else 1
    out = np.empty(image.shape, np.float32)
    for r in range(step):
        for c in range(step):
            plane = np.asarray(image[r::step, c::step], dtype=np.float32)
            out[r::step, c::step] = plane / _blur(plane, scale_px / step)
    finite = np.isfinite(out)
    if not finite.all():
        out[~finite] = 0.0
    np.clip(out, 0.0, 4.0, out=out)
    return out


def _blur(plane: np.ndarray, sigma: float) -> np.ndarray:
    """Large Gaussian-weighted local *linear* fit done on a shrunk copy (fast), floored to stay
    positive. Inside the frame it is the Gaussian blur; near the border a plain blur (any
    padding) flattens the vignetting slope and tilts the border micro-images, the local linear
    fit keeps the slope."""
    rows, cols = plane.shape
    factor = max(1, min(int(sigma // 4), rows // 8, cols // 8))
    small = cv2.resize(plane, (max(1, cols // factor), max(1, rows // factor)),
                       interpolation=cv2.INTER_AREA) if factor > 1 else plane
    level = float(np.mean(small))    # a constant is fitted exactly: keep rounding off it
    fit = small.astype(np.float64) - level
    for axis in (0, 1):
        fit = _local_linear_1d(fit, sigma / factor, axis)
    fit = (fit + level).astype(np.float32)
    blurred = cv2.resize(fit, (cols, rows), interpolation=cv2.INTER_LINEAR) \
        if factor > 1 else fit
    floor = max(float(np.mean(blurred)) * 1e-3, 1e-12)
    return np.maximum(blurred, floor)


def _local_linear_1d(f: np.ndarray, sigma: float, axis: int) -> np.ndarray:
    """Gaussian-weighted local linear fit along ``axis`` of a float64 image, over the frame only
    (no padding): the value at t of the line fitted to f(t') with weights g(t' - t)."""
    n = f.shape[axis]
    half = int(np.ceil(3 * sigma))
    kern = cv2.getGaussianKernel(2 * half + 1, sigma)[:, 0]
    t = np.arange(n, dtype=np.float64) - n / 2

    def g1d(a):   # the truncated sums along the line, (n,)
        return np.convolve(a, kern)[half:half + n]

    g0, g1, g2 = g1d(np.ones(n)), g1d(t), g1d(t * t)
    m1 = g1 - t * g0                       # moments of (t' - t)
    m2 = g2 - 2 * t * g1 + t * t * g0
    det = g0 * m2 - m1 * m1
    shape = (n, 1) if axis == 0 else (1, n)
    ca = (m2 / det).reshape(shape)   # a = ca G(f) + cb (G(t f) - t G(f))
    cb = (-m1 / det).reshape(shape)
    t_img = t.reshape(shape)
    one = np.ones((1, 1))
    kx, ky = (one, kern[:, None]) if axis == 0 else (kern[:, None], one)

    def g(a):
        return cv2.sepFilter2D(a, cv2.CV_64F, kx, ky, borderType=cv2.BORDER_CONSTANT)

    gf = g(f)
    return ca * gf + cb * (g(f * t_img) - t_img * gf)


# ----------------------------------------------------------------------------------------------
# 2-3. reciprocal lattice
def _rot(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


@dataclass(frozen=True)
class _Spectrum:
    z: np.ndarray          # (S, S//2+1) z-score of the log magnitude (rfft half plane)
    logmag: np.ndarray
    size: int
    valid: np.ndarray      # bins usable for peaks (not DC, not CFA Nyquist)

    def index(self, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bin (row, col) of frequencies f (..., 2) as (fx, fy) in cycles/px, folded into the
        half plane, and whether they are inside the band."""
        f = np.asarray(f, float)
        sign = np.where(f[..., 0] < 0, -1.0, 1.0)
        fx, fy = f[..., 0] * sign, f[..., 1] * sign
        inside = (np.abs(fx) < 0.5) & (np.abs(fy) < 0.5)
        col = np.rint(fx * self.size).astype(np.int64)
        row = np.rint(fy * self.size).astype(np.int64) % self.size
        col = np.clip(col, 0, self.z.shape[1] - 1)
        return row, col, inside

    def z_at(self, f: np.ndarray) -> np.ndarray:
        """Peak z-score near frequencies f (max over the 3 x 3 bins around each)."""
        row, col, inside = self.index(f)
        best = np.full(row.shape, -np.inf)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                r = (row + dr) % self.size
                c = np.clip(col + dc, 0, self.z.shape[1] - 1)
                best = np.maximum(best, np.where(self.valid[r, c], self.z[r, c], 0.0))
        return np.where(inside, best, 0.0)


def _spectrum(flat: np.ndarray, *, cfa: bool) -> _Spectrum:
    rows, cols = flat.shape
    size = min(rows, cols, FFT_CROP_PX)
    size -= size % 2
    r0, c0 = (rows - size) // 2, (cols - size) // 2
    crop = flat[r0:r0 + size, c0:c0 + size]
    win = np.hanning(size).astype(np.float32)
    data = (crop - np.float32(crop.mean())) * win[:, None] * win[None, :]
    spec = scipy.fft.rfft2(data, workers=-1)
    logmag = np.log(np.abs(spec) + 1e-12).astype(np.float64)
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    radius = np.hypot(fx, fy)
    # robust background per ring of 4 bins: median and (median - 16th percentile); the lattice
    # peaks are a minority of each ring, so they do not inflate it
    ring = np.minimum((radius * size / 4).astype(np.int64), size // 4 + 1).ravel()
    nring = size // 4 + 2
    # one float sort of (ring + normalised value) orders by ring, then by value
    lo, span = float(logmag.min()), float(np.ptp(logmag)) + 1e-9
    key = ring + (logmag.ravel() - lo) * (0.999 / span)
    key.sort()
    count = np.bincount(ring, minlength=nring)
    start = np.concatenate([[0], np.cumsum(count)[:-1]])
    sorted_vals = (key - np.repeat(np.arange(nring), count)) * (span / 0.999) + lo
    safe = np.maximum(count, 1)
    median = sorted_vals[np.minimum(start + safe // 2, sorted_vals.size - 1)]
    low = sorted_vals[np.minimum(start + (safe * 16) // 100, sorted_vals.size - 1)]
    mean = median
    std = np.maximum(median - low, 0.05)  # a perfectly flat field has no spread: no peak passes
    ring = ring.reshape(logmag.shape)
    z = (logmag - mean[ring]) / std[ring]
    valid = radius > 2.5 / size
    if cfa:  # residual mosaic: keep off the Nyquist corners
        for nx, ny in ((0.5, 0.0), (0.0, 0.5), (0.5, 0.5), (0.5, -0.5)):
            valid &= np.hypot(fx - nx, fy - ny) > 0.03
            valid &= np.hypot(fx - nx, fy + ny) > 0.03
    return _Spectrum(z=z, logmag=logmag, size=size, valid=valid)


def _ring_vectors(g: np.ndarray, lattice: str) -> list[np.ndarray]:
    """First three rings of the reciprocal lattice whose fundamental is ``g`` (2,)."""
    step = LATTICES[lattice]
    n = int(round(2 * np.pi / step))
    ring1 = [_rot(k * step) @ g for k in range(n)]
    if lattice == "hex":
        ring2 = [_rot(np.pi / 6 + k * step) @ g * np.sqrt(3) for k in range(n)]
    else:
        ring2 = [_rot(np.pi / 4 + k * step) @ g * np.sqrt(2) for k in range(n)]
    ring3 = [2 * v for v in ring1]
    return [np.array(ring1), np.array(ring2), np.array(ring3)]


SCORE_BAND = 0.45      # lattice hypotheses are scored on all their points up to this |f|
SCORE_TAU = 2.0        # a point must beat this z (the 3 x 3 max of pure background is ~1.5)


def _score(spec: _Spectrum, recip: np.ndarray) -> float:
    """Evidence for the lattice with reciprocal basis ``recip``: the sum over its first three
    rings (18 points for hex) of (z - tau). A lattice built on a harmonic sees only weaker
    harmonics; a lattice too fine (a false periodicity) pays tau for every empty point."""
    radius = min(SCORE_BAND, 2.05 * float(np.linalg.norm(recip, axis=1).max()))
    pts = _lattice_points(recip, radius)
    if len(pts) == 0:
        return -np.inf
    row, col, inside = spec.index(pts)
    z = spec.z_at(pts)
    usable = inside & spec.valid[row, col]
    return float(np.sum(np.clip(z[usable], -2.0, 30.0) - SCORE_TAU))


def _lattice_points(recip: np.ndarray, kmax: float) -> np.ndarray:
    """Points m g1 + n g2 with 0 < |f| <= kmax, one of each +-pair (fx >= 0)."""
    g1, g2 = recip
    area = abs(g1[0] * g2[1] - g1[1] * g2[0])
    n = int(np.ceil(kmax * max(np.linalg.norm(g1), np.linalg.norm(g2)) / area)) + 1
    m, k = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij")
    pts = m.ravel()[:, None] * g1 + k.ravel()[:, None] * g2
    norm = np.linalg.norm(pts, axis=1)
    keep = (norm > 0) & (norm <= kmax) & ((pts[:, 0] > 0) | ((pts[:, 0] == 0) & (pts[:, 1] > 0)))
    return pts[keep]


def _find_fundamental(spec: _Spectrum, lattice: str, *, strict: bool = True
                      ) -> tuple[np.ndarray | None, float, list[tuple[np.ndarray, float]]]:
    """The reciprocal basis (2, 2) (rows g1, g2, cycles/px) of the best-supported lattice, its
    score, and every hypothesis tried as (basis, score); with ``strict`` False, (None, -inf or
    the best score, hypotheses) instead of an error when no lattice stands out. Candidates: each
    strong peak taken as a fundamental, then as a harmonic of a finer lattice (g/2, g/sqrt(3)
    turned 30 deg for hex; g/2, g/sqrt(2) turned 45 deg square)."""
    z = np.where(spec.valid, spec.z, -np.inf)
    size = spec.size
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    radius = np.hypot(fx, fy)
    step = LATTICES[lattice]
    scale = 1.0 if lattice == "square" else 1.0 / np.sin(np.pi / 3)
    fmin, fmax = scale / PITCH_RANGE_PX[1], scale / PITCH_RANGE_PX[0]
    local = cv2.dilate(z.astype(np.float32), np.ones((5, 5), np.uint8))
    peaks = np.argwhere((z >= local) & (radius >= fmin) & (radius <= 2 * fmax) & (z > PEAK_Z))
    if len(peaks) == 0:
        if not strict:
            return None, -np.inf, []
        raise CalibrationError("no micro-lens lattice found: the image spectrum has no periodic "
                               f"peaks for pitches {PITCH_RANGE_PX[0]:g}-{PITCH_RANGE_PX[1]:g} px; "
                               "pass a white image (or a scene) taken through the lens array")
    order = np.argsort(-z[peaks[:, 0], peaks[:, 1]])[:16]
    best, best_recip = -np.inf, None
    tried: list[np.ndarray] = []
    candidates: list[tuple[np.ndarray, float]] = []
    for r, c in peaks[order]:
        g0 = _subbin_peak(spec, r, c)
        finer = [g0, g0 / 2] + ([_rot(np.pi / 6) @ g0 / np.sqrt(3)] if lattice == "hex"
                                else [_rot(np.pi / 4) @ g0 / np.sqrt(2)])
        for g in finer:
            if not fmin <= np.linalg.norm(g) <= fmax:
                continue
            if any(_same_lattice(g, t, step) for t in tried):
                continue
            tried.append(g)
            recip = _refine_reciprocal(spec, g, lattice, kmax=min(SCORE_BAND,
                                                                  3.1 * np.linalg.norm(g)))
            s = _score(spec, recip)
            candidates.append((recip, s))
            if s > best:
                best, best_recip = s, recip
    if best_recip is None or best <= 0:
        if not strict:
            return None, best, candidates
        raise CalibrationError("no micro-lens lattice found: spectral peaks exist but none forms "
                               f"a {lattice} lattice; check --lattice, or pass a white image")
    # the best hypothesis may still be a harmonic lattice when the fundamentals are weak (white
    # images whose micro-images fill their cells): take a finer lattice when its own first ring
    # is clearly present
    for _ in range(3):
        g = best_recip[0]
        finer = [g / 2, (_rot(np.pi / 6) @ g / np.sqrt(3)) if lattice == "hex"
                 else (_rot(np.pi / 4) @ g / np.sqrt(2))]
        for cand in finer:
            if np.linalg.norm(cand) < fmin:
                continue
            z1 = spec.z_at(_ring_vectors(cand, lattice)[0])
            if np.sum(z1 > PEAK_Z) >= len(z1) - 1:
                best_recip = _refine_reciprocal(spec, cand, lattice, kmax=min(
                    SCORE_BAND, 3.1 * np.linalg.norm(cand)))
                break
        else:
            break
    return best_recip, best, candidates


def _same_lattice(g: np.ndarray, other: np.ndarray, step: float) -> bool:
    if abs(np.linalg.norm(g) - np.linalg.norm(other)) > 0.02 * np.linalg.norm(g):
        return False
    da = (np.arctan2(g[1], g[0]) - np.arctan2(other[1], other[0])) % step
    return min(da, step - da) < 0.02


def _subbin_peak(spec: _Spectrum, r: int, c: int) -> np.ndarray:
    size, lm = spec.size, spec.logmag
    ox = _parabola(lm[r, c - 1], lm[r, c], lm[r, c + 1]) if 0 < c < lm.shape[1] - 1 else 0.0
    oy = _parabola(lm[(r - 1) % size, c], lm[r, c], lm[(r + 1) % size, c])
    fy_bin = r if r < size // 2 else r - size
    return np.array([(c + ox) / size, (fy_bin + oy) / size])


def _refine_reciprocal(spec: _Spectrum, g: np.ndarray, lattice: str, *,
                       kmax: float) -> np.ndarray:
    """Least-squares reciprocal basis (2, 2) (rows g1, g2) from every clear harmonic peak with
    |f| <= kmax, nearest first (each refit predicts the next harmonics better)."""
    basis = np.array([g, _rot(LATTICES[lattice]) @ g])
    radius = min(kmax, 3.1 * np.linalg.norm(g))
    while True:
        basis = _fit_peaks(spec, basis, radius)
        if radius >= kmax:
            return basis
        radius = min(kmax, 2 * radius)


def _fit_peaks(spec: _Spectrum, basis: np.ndarray, kmax: float) -> np.ndarray:
    g1, g2 = basis
    area = abs(g1[0] * g2[1] - g1[1] * g2[0])
    n = int(np.ceil(kmax * max(np.linalg.norm(g1), np.linalg.norm(g2)) / area)) + 1
    rows, labels, weights = [], [], []
    size, lm = spec.size, spec.logmag
    for m in range(-n, n + 1):
        for k in range(-n, n + 1):
            f = m * g1 + k * g2
            if not 0 < np.linalg.norm(f) <= kmax or f[0] < 0 or (f[0] == 0 and f[1] < 0):
                continue
            r, c, inside = spec.index(f)
            if not inside or c < 2 or c >= spec.z.shape[1] - 2:
                continue
            win = spec.z[(r + np.arange(-1, 2))[:, None] % size, c + np.arange(-1, 2)[None, :]]
            dr, dc = np.unravel_index(np.argmax(win), win.shape)
            pr, pc = (r + dr - 1) % size, c + dc - 1
            if spec.z[pr, pc] < PEAK_Z or not spec.valid[pr, pc]:
                continue
            ox = _parabola(lm[pr, pc - 1], lm[pr, pc], lm[pr, pc + 1])
            oy = _parabola(lm[(pr - 1) % size, pc], lm[pr, pc], lm[(pr + 1) % size, pc])
            fy_bin = pr if pr < size // 2 else pr - size
            rows.append([(pc + ox) / size, (fy_bin + oy) / size])
            labels.append([m, k])
            weights.append(min(spec.z[pr, pc], 40.0))
    lab = np.array(labels, float).reshape(-1, 2)
    if len(rows) < 3 or np.linalg.matrix_rank(lab) < 2:
        return basis
    f_obs, w = np.array(rows), np.sqrt(np.array(weights))
    fitted, *_ = np.linalg.lstsq(lab * w[:, None], f_obs * w[:, None], rcond=None)
    return fitted


def _parabola(a: float, b: float, c: float) -> float:
    den = a - 2 * b + c
    return 0.0 if den >= 0 else float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))


def _direct_from_reciprocal(recip: np.ndarray, lattice: str) -> tuple[float, float]:
    """Pitch (px) and angle (rad, reduced to one period of the lattice) of the similarity lattice
    closest to the reciprocal basis ``recip`` (rows g1, g2)."""
    direct = np.linalg.inv(recip).T  # rows b1, b2 with b_i . g_j = delta_ij
    step = LATTICES[lattice]
    rot = _rot(step)
    # b2 may be +step or -step from b1 (or the pair reversed); pick the arrangement that fits
    best = None
    for b1, b2 in ((direct[0], direct[1]), (direct[1], direct[0]),
                   (direct[0], -direct[1]), (-direct[1], direct[0])):
        s = (b1 + rot.T @ b2) / 2
        err = np.linalg.norm(b1 - s) + np.linalg.norm(b2 - rot @ s)
        if best is None or err < best[0]:
            best = (err, s)
    s = best[1]
    return float(np.hypot(*s)), float(np.arctan2(s[1], s[0]) % step)


def _phase_offset(flat: np.ndarray, grid: LensGrid) -> tuple[float, float]:
    """A lattice point from the phases of the fundamentals (direct DFT over a central crop)."""
    rows, cols = flat.shape
    size_r, size_c = min(rows, 2 * FFT_CROP_PX), min(cols, 2 * FFT_CROP_PX)
    r0, c0 = (rows - size_r) // 2, (cols - size_c) // 2
    crop = flat[r0:r0 + size_r, c0:c0 + size_c].astype(np.float64)
    wr, wc = np.hanning(size_r), np.hanning(size_c)
    crop = (crop - crop.mean()) * wr[:, None] * wc[None, :]
    xc, yc = c0 + (size_c - 1) / 2, r0 + (size_r - 1) / 2
    x = np.arange(size_c) - (size_c - 1) / 2
    y = np.arange(size_r) - (size_r - 1) / 2
    direct = grid.basis()
    recip = np.linalg.inv(direct).T
    frac = []
    for g in recip:
        coeff = np.exp(-2j * np.pi * g[1] * y) @ crop @ np.exp(-2j * np.pi * g[0] * x)
        frac.append(-np.angle(coeff) / (2 * np.pi))   # g . (x0 - centre) mod 1
    x0 = np.array([xc, yc]) + frac[0] * direct[0] + frac[1] * direct[1]
    return float(x0[0]), float(x0[1])


# ----------------------------------------------------------------------------------------------
# 2b. ambiguous spectra (scene images): lattice hypotheses scored by the micro-image borders
CONFIDENT_Z = 8.0      # every point of the first two rings above this: the spectrum is decisive
FOLD_MAX_PX = 1024     # the fold is evaluated over a central region of at most this side
# a finer relative (pitch / sqrt(3) turned 30 deg, pitch / 2) replaces a lattice when it keeps
# this share of its contrast. A false finer lattice mixes 3 (4) cell positions: about 1/3 of
# the contrast for sqrt(3) and 1/2 for 2 (a honeycomb shifted by half a lattice vector overlaps
# itself in part); the true lattice keeps about 1 against a coarser relative, down to ~0.55
# against sqrt(3) on a multi-focus array whose three lens types (a sqrt(3) sub-lattice each)
# differ in sharpness.
FINER_KEEP = {"sqrt": 0.45, "half": 0.75}
# the fold's rotation is good to about this many rad times 1 / (side of the fold region in px)
# (1/8 of its quadratic-fit grid step; R42 crop: 0.009 deg from the XML = 0.3 of a step).
# A lattice fitted through scene centres is kept when its standard error is smaller (large
# frames: origami 0.001 deg against a fold precision of 0.004 deg)
FOLD_ANGLE_PRECISION = 0.0625
FOLD_CONTROL = 3.0     # the winner's contrast must beat detuned copies of it this many times
HYPOTHESES_PER_SPECTRUM = 6   # strongest spectral lattices taken from each spectrum
FOLD_REFINE = 6        # hypotheses refined locally (by their first fold contrast)


def _spectrum_is_decisive(spec: _Spectrum, recip: np.ndarray, lattice: str) -> bool:
    """A white image shows every point of the first two reciprocal rings as a strong peak; a
    scene image (parallax-repeated content, weak or missing lattice peaks) does not."""
    rings = _ring_vectors(recip[0], lattice)[:2]
    z = np.concatenate([spec.z_at(r) for r in rings])
    return bool(np.all(z >= CONFIDENT_Z))


def _gradient_magnitude(flat: np.ndarray) -> np.ndarray:
    """|grad| of a flattened image (central differences), clipped at its 99th percentile so a few
    strong scene edges do not dominate the fold."""
    gx = cv2.Sobel(flat, cv2.CV_32F, 1, 0, ksize=1)
    gy = cv2.Sobel(flat, cv2.CV_32F, 0, 1, ksize=1)
    grad = np.sqrt(gx * gx + gy * gy)
    return np.minimum(grad, np.float32(np.percentile(grad, 99)))


FOLD_BIN_PX = 1.0      # fold bin size (px): the same sharpness scale for every pitch
FOLD_SMOOTH_PX = 2.0   # folded structure broader than this (px) is removed (scene stripes)


@numba.njit(cache=True)
def _fold_sums(grad, inv00, inv01, inv10, inv11, bins):  # pragma: no cover - compiled
    """Sum and count of ``grad`` per bin of the fractional lattice coordinates
    (u, v) = inv @ (x, y) (x, y relative to the region centre), ``bins`` per unit, separately
    for the four quadrants of the region: (4, bins^2) each."""
    rows, cols = grad.shape
    total = np.zeros((4, bins * bins))
    count = np.zeros((4, bins * bins))
    xc, yc = (cols - 1) / 2, (rows - 1) / 2
    for r in range(rows):
        y = r - yc
        qr = 2 * ((2 * r) // rows)
        for c in range(cols):
            x = c - xc
            u = (inv00 * x + inv01 * y) * bins
            v = (inv10 * x + inv11 * y) * bins
            q = qr + (2 * c) // cols
            k = (int(np.floor(u)) % bins) * bins + int(np.floor(v)) % bins
            total[q, k] += grad[r, c]
            count[q, k] += 1.0
    return total, count


@dataclass(frozen=True)
class _Fold:
    """Gradient magnitude of a region, ready to be folded onto lattice cells."""

    grad: np.ndarray      # (rows, cols) float32
    mean_sq: float        # mean of grad, squared (normalisation)

    @classmethod
    def of(cls, grad: np.ndarray) -> _Fold:
        grad = np.ascontiguousarray(grad, np.float32)
        return cls(grad=grad, mean_sq=max(float(np.mean(grad)) ** 2, 1e-24))

    def _fold(self, pitch_px: float, angle_rad: float, lattice: str):
        """Sums and counts of the gradient folded onto one cell (per quadrant), the bins per
        side, and the lattice basis (rows b1, b2, px)."""
        step = LATTICES[lattice]
        bins = max(8, int(round(pitch_px / FOLD_BIN_PX)))
        basis = pitch_px * np.array([[np.cos(angle_rad), np.sin(angle_rad)],
                                     [np.cos(angle_rad + step), np.sin(angle_rad + step)]])
        inv = np.linalg.inv(basis.T)
        total, count = _fold_sums(self.grad, inv[0, 0], inv[0, 1], inv[1, 0], inv[1, 1], bins)
        return total, count, bins, basis

    def contrast(self, pitch_px: float, angle_rad: float, lattice: str) -> float:
        """Border contrast of the lattice (pitch, angle): every pixel's gradient magnitude is
        folded onto one lattice cell (bins of about 1 x 1 px of the fractional lattice
        coordinates), separately for the four quadrants of the region; the smooth part (> 2 px)
        of each folded mean is removed and the result is the mean covariance of the quadrant
        pairs over the squared mean gradient. Scene content shifts from lens to lens
        (parallax) and blurs out in the fold; what is left of it, and a local repetition of
        the scene (the parallax repeats it with a depth-dependent period), differs between
        quadrants and averages out of the covariance (unlike a variance, which also grows
        with the number of bins by chance); the micro-image borders are common to all. They
        add up only on the true lattice or a coarser one containing it (the same
        contrast); a finer one mixes several cell positions (about 1/3 or less). The smooth
        part goes because a scene periodicity folds into broad stripes. Independent of the
        offset (a shift of the fold is a cyclic shift of its bins)."""
        total, count, bins, _ = self._fold(pitch_px, angle_rad, lattice)
        mean = (total / np.maximum(count, 1)).reshape(4, bins, bins)
        filled = (count > 0).reshape(4, bins, bins)
        if not filled.all():   # a rational pitch / row ratio can leave bins empty
            f = filled.astype(np.float64)
            near = _wrap_blur(mean * f, 1.0) / np.maximum(_wrap_blur(f, 1.0), 1e-9)
            mean = np.where(filled, mean, near)
        fine = mean - _wrap_blur(mean, FOLD_SMOOTH_PX * bins / pitch_px)
        fine = fine.reshape(4, -1)
        pairs = fine.sum(axis=0) ** 2 - (fine ** 2).sum(axis=0)   # 2 x sum over pairs
        return float(np.mean(pairs)) / (12 * self.mean_sq)

    def centre(self, pitch_px: float, angle_rad: float, lattice: str) -> np.ndarray:
        """A micro-image centre (x, y) px relative to the region centre, to about half a pixel:
        the point of the folded borders that is both a 2-fold and a 3-fold (hex) or 4-fold
        (square) symmetry centre. The honeycomb of borders is also point-symmetric about its
        edge midpoints and 3-fold about its vertices; only the cell centre is both."""
        total, count, bins, basis = self._fold(pitch_px, angle_rad, lattice)
        mean = (total.sum(0) / np.maximum(count.sum(0), 1)).reshape(bins, bins)
        fine = mean - _wrap_blur(mean[None], FOLD_SMOOTH_PX * bins / pitch_px)[0]
        d = np.arange(bins)
        du, dv = np.meshgrid(d, d, indexing="ij")
        # rotations about bin (0, 0) in lattice coordinates: by 180 deg, and by 120 deg (hex:
        # b1 -> b2 - b1, b2 -> -b1) or 90 deg (square: b1 -> b2, b2 -> -b1)
        turn = ((-du - dv) % bins, du) if lattice == "hex" else ((-dv) % bins, du)
        flip = ((-du) % bins, (-dv) % bins)
        score = np.empty((bins, bins))
        for cu in range(bins):
            for cv in range(bins):
                f = np.roll(fine, (-cu, -cv), axis=(0, 1))   # candidate centre at (0, 0)
                score[cu, cv] = np.sum(f * f[flip]) + np.sum(f * f[turn])
        cu, cv = np.unravel_index(np.argmax(score), score.shape)
        su = _parabola(score[(cu - 1) % bins, cv], score[cu, cv], score[(cu + 1) % bins, cv])
        sv = _parabola(score[cu, (cv - 1) % bins], score[cu, cv], score[cu, (cv + 1) % bins])
        uv = (np.array([cu + su, cv + sv]) + 0.5) / bins
        return uv @ basis


def _wrap_blur(a: np.ndarray, sigma: float) -> np.ndarray:
    from scipy import ndimage

    return ndimage.gaussian_filter(a, (0, sigma, sigma), mode="wrap")   # (4, bins, bins)


def _refine_by_fold(fold: _Fold, pitch: float, angle: float, lattice: str, *,
                    span: float, evaluations: int) -> tuple[float, float, float]:
    """Local maximum of the border contrast around (pitch, angle): Nelder-Mead in (log pitch,
    angle) with an initial step of ``span`` (relative pitch, rad), at most ``evaluations``
    folds. Returns pitch px, angle rad, contrast."""
    from scipy.optimize import minimize

    def cost(p):
        return -fold.contrast(pitch * np.exp(p[0]), angle + p[1], lattice)

    res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                   options={"initial_simplex": [[0, 0], [span, 0], [0, span]],
                            "xatol": 1e-6, "fatol": 0, "maxfev": evaluations})
    return float(pitch * np.exp(res.x[0])), float(angle + res.x[1]), float(-res.fun)


def _fold_peak(fold: _Fold, pitch: float, angle: float, lattice: str) -> tuple[float, float]:
    """Centre of a quadratic fitted to the contrast on a 7 x 7 grid around (pitch, angle): the
    binned contrast is bumpy at the scale of a few hundredths of a degree, the fit averages
    the bumps. The grid spans +-3/4 of the detuning that shifts the region's edge by 1 px."""
    rows, cols = fold.grad.shape
    h = 0.5 / max(rows, cols)       # relative pitch step and angle step (rad)
    k = np.arange(-3, 4) * h
    dp, da = np.meshgrid(k, k, indexing="ij")
    c = np.array([fold.contrast(pitch * (1 + x), angle + y, lattice)
                  for x, y in zip(dp.ravel(), da.ravel(), strict=True)])
    x, y = dp.ravel() / h, da.ravel() / h
    a = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    q, *_ = np.linalg.lstsq(a, c, rcond=None)
    hess = np.array([[2 * q[3], q[4]], [q[4], 2 * q[5]]])
    if not (np.all(np.linalg.eigvalsh(hess) < 0)):
        return pitch, angle
    peak = np.linalg.solve(hess, -q[1:3])
    if np.any(np.abs(peak) > 3):    # outside the grid: keep the direct optimum
        return pitch, angle
    return pitch * (1 + peak[0] * h), angle + peak[1] * h


def _relatives(pitch: float, angle: float, lattice: str) -> list[tuple[float, float]]:
    """The lattice, its sub-lattices of index 3 / 4 (hex) or 2 / 4 (square) and the finer
    lattices it is a sub-lattice of: a spectral peak may be a harmonic or a sub-harmonic."""
    turn, root = (np.pi / 6, np.sqrt(3)) if lattice == "hex" else (np.pi / 4, np.sqrt(2))
    return [(pitch, angle), (pitch * root, angle + turn), (pitch / root, angle + turn),
            (pitch * 2, angle), (pitch / 2, angle)]


def _windows(shape: tuple[int, int], size: int) -> list[tuple[int, int]]:
    """Top-left corners of square windows of ``size`` at the start, middle and end of the long
    side (even, to keep the CFA phase); one window for a square image."""
    rows, cols = shape
    out = []
    for fr in (0.0, 0.5, 1.0):
        r0, c0 = int(fr * (rows - size)), int(fr * (cols - size))
        r0, c0 = r0 - r0 % 2, c0 - c0 % 2
        if (r0, c0) not in out:
            out.append((r0, c0))
    return out


def _hypotheses(image: np.ndarray, cfa: str | None, lattice: str
                ) -> tuple[list[tuple[float, float]], list[_Spectrum]]:
    """Lattice hypotheses (pitch px, angle rad): the strongest spectral lattices of the
    intensity and gradient-magnitude spectra of square windows along the
    frame, with their harmonic and sub-harmonic relatives; and the intensity spectra."""
    rows, cols = image.shape
    size = min(rows, cols, FFT_CROP_PX)
    size -= size % 2
    spectra = []
    for r0, c0 in _windows((rows, cols), size):
        flat = flatten(image[r0:r0 + size, c0:c0 + size], cfa=cfa)
        spectra.append(_spectrum(flat, cfa=bool(cfa)))
        spectra.append(_spectrum(_gradient_magnitude(flat), cfa=bool(cfa)))
    step = LATTICES[lattice]
    out: list[tuple[float, float]] = []
    for spec in spectra:
        _, _, cands = _find_fundamental(spec, lattice, strict=False)
        cands = [c for c in cands if c[1] > 0]   # some evidence of a whole lattice
        for recip, _ in sorted(cands, key=lambda t: -t[1])[:HYPOTHESES_PER_SPECTRUM]:
            for pitch, angle in _relatives(*_direct_from_reciprocal(recip, lattice), lattice):
                if not PITCH_RANGE_PX[0] <= pitch <= PITCH_RANGE_PX[1]:
                    continue
                angle %= step
                if any(abs(pitch / p - 1) < 0.01 and abs((angle - a + step / 2) % step
                                                         - step / 2) < 0.01 for p, a in out):
                    continue
                out.append((pitch, angle))
    return out, spectra[::2]


def _fundamental_seen(spectra: list[_Spectrum], pitch: float, angle: float,
                      lattice: str) -> bool:
    """Whether the intensity spectra show the first reciprocal ring of the lattice (mean z over
    its points and the spectra above PEAK_Z): then the lattice is real periodic structure and a
    finer relative (which has no peaks there) is not the lens lattice, however sharply it
    folds. A multi-focus array's coarser lens-type lattice shows no such ring on a scene."""
    grid = LensGrid(pitch, angle, (0.0, 0.0), lattice)
    g = np.linalg.inv(grid.basis()).T[0]
    ring = _ring_vectors(g, lattice)[0]
    return bool(np.mean([np.mean(spec.z_at(ring)) for spec in spectra]) > PEAK_Z)


def _lattice_by_fold(image: np.ndarray, cfa: str | None, lattice: str
                     ) -> tuple[float, float, float, tuple[float, float]]:
    """(pitch px, angle rad, contrast, a lens centre (x, y) px) of the hypothesis whose
    micro-image borders fold sharpest, refined locally, at the scale where no finer or coarser
    relative folds clearly better (see FINER_KEEP)."""
    rows, cols = image.shape
    r0, c0 = max(0, (rows - FOLD_MAX_PX) // 2), max(0, (cols - FOLD_MAX_PX) // 2)
    r0, c0 = r0 - r0 % 2, c0 - c0 % 2
    region = image[r0:r0 + FOLD_MAX_PX, c0:c0 + FOLD_MAX_PX]
    hyps, spectra = _hypotheses(image, cfa, lattice)
    if not hyps:
        raise CalibrationError("no micro-lens lattice found: the image spectrum has no periodic "
                               f"peaks for pitches {PITCH_RANGE_PX[0]:g}-{PITCH_RANGE_PX[1]:g} px; "
                               "pass a white image (or a scene) taken through the lens array")
    median_pitch = float(np.median([p for p, _ in hyps]))
    fold = _Fold.of(_gradient_magnitude(flatten(region, cfa=cfa,
                                                 scale_px=max(FLAT_SCALE * median_pitch, 8.0))))
    def refined(p, a):
        return _refine_by_fold(fold, p, a, lattice, span=0.004, evaluations=40)

    scored = sorted(((fold.contrast(p, a, lattice), p, a) for p, a in hyps), reverse=True)
    pitch, angle, best = max((refined(p, a) for _, p, a in scored[:FOLD_REFINE]),
                             key=lambda t: t[2])
    for _ in range(3):   # walk the scale: the lattice, not a finer or coarser relative
        near = _relatives(pitch, angle, lattice)
        moves = []
        for k, (p, a) in enumerate(near[1:]):
            keep = FINER_KEEP["sqrt" if k < 2 else "half"]
            if k % 2 == 0 and p <= PITCH_RANGE_PX[1]:      # coarser
                moves.append((refined(p, a), 1 / keep))
            elif k % 2 == 1 and p >= PITCH_RANGE_PX[0] and not _fundamental_seen(
                    spectra, pitch, angle, lattice):   # finer, unless the spectrum shows ours
                moves.append((refined(p, a), keep))
        better = [m for m, need in moves if m[2] >= need * best]
        if not better:
            break
        pitch, angle, best = max(better, key=lambda t: t[2])
    pitch, angle, best = _refine_by_fold(fold, pitch, angle, lattice, span=0.001, evaluations=80)
    pitch, angle = _fold_peak(fold, pitch, angle, lattice)
    control = max(fold.contrast(pitch * f, angle + da, lattice)
                  for f, da in ((1.03, 0.0), (0.97, 0.0), (1.0, 0.05), (1.0, -0.05)))
    if not best > FOLD_CONTROL * max(control, 0.0):
        raise CalibrationError("no micro-lens lattice found: no lattice hypothesis shows "
                               "micro-image borders; pass a white image (or a scene) taken "
                               "through the lens array")
    rows_r, cols_r = region.shape
    centre = fold.centre(pitch, angle, lattice) + np.array([c0 + (cols_r - 1) / 2,
                                                            r0 + (rows_r - 1) / 2])
    return pitch, angle, best, (float(centre[0]), float(centre[1]))


# ----------------------------------------------------------------------------------------------
# 4. per-lens centres
@numba.njit(parallel=True, cache=True)
def _symmetry_centres(values, cx, cy, radius, n_iter):  # pragma: no cover - compiled
    """Gauss-Newton point-symmetry centres: minimise sum_k w(|x_k - c|) (I(x_k) - I(2c - x_k))^2
    over the pixels x_k of a disc of ``radius`` around c; I(2c - x_k) bilinear."""
    rows, cols = values.shape
    out_x = cx.copy()
    out_y = cy.copy()
    ok = np.ones(cx.shape[0], np.bool_)
    r2 = radius * radius
    for k in numba.prange(cx.shape[0]):
        x, y = cx[k], cy[k]
        for _ in range(n_iter):
            r_lo, r_hi = int(np.ceil(y - radius)), int(np.floor(y + radius))
            c_lo, c_hi = int(np.ceil(x - radius)), int(np.floor(x + radius))
            if (r_lo < 1 or c_lo < 1 or r_hi > rows - 2 or c_hi > cols - 2
                    or 2 * y - r_hi < 0 or 2 * x - c_hi < 0
                    or 2 * y - r_lo > rows - 2 or 2 * x - c_lo > cols - 2):
                ok[k] = False
                break
            a11 = 0.0
            a12 = 0.0
            a22 = 0.0
            b1 = 0.0
            b2 = 0.0
            # the mirror 2c - x_k of every pixel has the same fractional part: one set of
            # bilinear weights per iteration
            fx2, fy2 = np.floor(2 * x), np.floor(2 * y)
            fx, fy = 2 * x - fx2, 2 * y - fy2
            ix2, iy2 = int(fx2), int(fy2)
            for r in range(r_lo, r_hi + 1):
                dy = r - y
                j0 = iy2 - r
                for c in range(c_lo, c_hi + 1):
                    dx = c - x
                    d2 = dx * dx + dy * dy
                    if d2 >= r2:
                        continue
                    t = 1.0 - d2 / r2
                    w = t * t
                    i0 = ix2 - c
                    v00 = values[j0, i0]
                    v01 = values[j0, i0 + 1]
                    v10 = values[j0 + 1, i0]
                    v11 = values[j0 + 1, i0 + 1]
                    top = v00 + fx * (v01 - v00)
                    bot = v10 + fx * (v11 - v10)
                    e = values[r, c] - (top + fy * (bot - top))
                    jx = -2.0 * ((1 - fy) * (v01 - v00) + fy * (v11 - v10))
                    jy = -2.0 * (bot - top)
                    a11 += w * jx * jx
                    a12 += w * jx * jy
                    a22 += w * jy * jy
                    b1 += w * jx * e
                    b2 += w * jy * e
            det = a11 * a22 - a12 * a12
            if det <= 0.0:
                ok[k] = False
                break
            sx = -(a22 * b1 - a12 * b2) / det
            sy = -(a11 * b2 - a12 * b1) / det
            step = np.hypot(sx, sy)
            if step > 0.1 * radius:   # far from the fixed point: damp
                sx *= 0.1 * radius / step
                sy *= 0.1 * radius / step
            x += sx
            y += sy
            if step < 1e-3:
                break
        out_x[k] = x
        out_y[k] = y
    return out_x, out_y, ok


def refine_centres(flat: np.ndarray, grid: LensGrid, *, window: float = 0.6,
                   n_iter: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-lens centres as point-symmetry centres of the micro-images.

    Each centre c minimises sum_k w(|x_k - c|) (I(x_k) - I(2c - x_k))^2 over the pixels x_k
    within ``window`` pitches of c (Gauss-Newton from the lattice position; w a smooth taper,
    I(2c - x_k) bilinear). A plain centroid weighs the flat top of a micro-image and ignores its
    edges, which carry the position; the symmetry fit uses the edges, and neighbours that
    overlap the window only add noise, not a systematic pull, as long as they are symmetric on
    average.

    Parameters
    ----------
    flat : (rows, cols) float32 flattened image (see :func:`flatten`, blur of >= 1 pitch: a
        narrower blur follows each lens's neighbours and tilts its micro-image)
    grid : the lattice to start from
    window : radius of the symmetry disc in units of the pitch

    Returns
    -------
    indices (K, 2) int, centres (K, 2) float (x, y) px, refined (K,) bool
        Every lattice lens whose ideal centre is inside the image; lenses whose disc (or its
        mirror) leaves the image keep their ideal centre (refined False).
    """
    rows, cols = flat.shape
    grid = LensGrid(grid.pitch_px, grid.angle_rad, grid.offset_xy, grid.lattice,
                    image_shape=(rows, cols))
    idx, ideal = grid.lens_centres()
    radius = window * grid.pitch_px
    margin = radius + EDGE_MARGIN * grid.pitch_px + 2  # flattening is less sure at the border
    inner = ((ideal[:, 0] >= margin) & (ideal[:, 0] <= cols - 1 - margin)
             & (ideal[:, 1] >= margin) & (ideal[:, 1] <= rows - 1 - margin))
    cx, cy, ok = _symmetry_centres(np.ascontiguousarray(flat, np.float32),
                                   ideal[inner, 0].copy(), ideal[inner, 1].copy(),
                                   float(radius), n_iter)
    refined = np.zeros(len(ideal), bool)
    refined[np.flatnonzero(inner)[ok]] = True
    centres = ideal.copy()
    centres[inner, 0] = np.where(ok, cx, ideal[inner, 0])
    centres[inner, 1] = np.where(ok, cy, ideal[inner, 1])
    return idx, centres, refined


# ----------------------------------------------------------------------------------------------
# 5. lattice fit
def fit_lattice(indices: np.ndarray, centres: np.ndarray, *, lattice: str = "hex",
                weights: np.ndarray | None = None) -> tuple[float, float, tuple[float, float]]:
    """Least-squares similarity lattice through lens centres.

    ``x_ij = o + i b1 + j R(step) b1`` is linear in (o, b1), so this is one linear solve.

    Parameters
    ----------
    indices : (K, 2) lattice indices (i, j)
    centres : (K, 2) centres (x, y) in px
    weights : (K,) optional weights (0 drops a lens)

    Returns
    -------
    pitch_px, angle_rad (unreduced), offset_xy (the centre of lens (0, 0))
    """
    if lattice not in LATTICES:
        raise ValueError(f"lattice must be one of {sorted(LATTICES)}, got {lattice!r}")
    i = np.asarray(indices[:, 0], float)
    j = np.asarray(indices[:, 1], float)
    cs, sn = np.cos(LATTICES[lattice]), np.sin(LATTICES[lattice])
    ones, zeros = np.ones_like(i), np.zeros_like(i)
    # unknowns (ox, oy, u, v); b1 = (u, v), b2 = (cs u - sn v, sn u + cs v)
    ax = np.stack([ones, zeros, i + j * cs, -j * sn], axis=1)
    ay = np.stack([zeros, ones, j * sn, i + j * cs], axis=1)
    a = np.concatenate([ax, ay])
    b = np.concatenate([centres[:, 0], centres[:, 1]])
    if weights is not None:
        w = np.sqrt(np.concatenate([weights, weights]))
        a, b = a * w[:, None], b * w
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    ox, oy, u, v = sol
    return float(np.hypot(u, v)), float(np.arctan2(v, u)), (float(ox), float(oy))


def _reindexed(pitch: float, angle: float, offset: tuple[float, float], lattice: str,
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


def calibrate(image: np.ndarray, *, lattice: str = "hex", cfa: str | None = None,
              black_level: float = 0.0, refine: bool = True) -> tuple[LensGrid, CalibrationReport]:
    """Estimate the micro-lens lattice and every micro-image centre from one image.

    Parameters
    ----------
    image : (rows, cols) array
        A white image (best) or a scene image taken through the lens array; raw Bayer mosaics
        are fine when ``cfa`` names the pattern at pixel (0, 0).
    lattice : "hex" or "square"
    cfa : Bayer pattern at (0, 0) or None
    black_level : DN subtracted first (a pedestal would leave the vignetting tilt in the
        flattened micro-images and bias their centres)
    refine : also refine each lens centre (otherwise the grid holds the lattice only)

    Returns
    -------
    grid : LensGrid with pitch_px, angle_rad in [0, 60 deg) (hex) or [0, 90 deg) (square),
        offset_xy = centre of the lens nearest the image centre, ``image_shape``, and (when
        ``refine``) ``centres_xy`` / ``indices`` of every lens inside the image.
    report : residuals of the refined centres against the fitted lattice.
    """
    if lattice not in LATTICES:
        raise ValueError(f"lattice must be one of {sorted(LATTICES)}, got {lattice!r}")
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError(f"image must be 2-D (rows, cols), got shape {image.shape}")
    rows, cols = image.shape
    if min(rows, cols) < MIN_SIDE_PX:
        raise CalibrationError(f"image of {cols} x {rows} px is too small to calibrate a lens "
                               f"grid; it needs at least {MIN_SIDE_PX} px on each side")
    image = image.astype(np.float32) - np.float32(black_level) if black_level else image
    # coarse search on a flattened central crop; the whole frame is flattened once the pitch is
    # known, with a blur of 1.5 pitch: it follows the vignetting (no tilt left inside a
    # micro-image, which would pull the centres) and still averages the lattice out
    size = min(rows, cols, FFT_CROP_PX)
    r0, c0 = (rows - size) // 2, (cols - size) // 2
    r0, c0 = r0 - r0 % 2, c0 - c0 % 2   # keep the CFA phase
    spec = _spectrum(flatten(image[r0:r0 + size, c0:c0 + size], cfa=cfa), cfa=bool(cfa))
    recip, score, _ = _find_fundamental(spec, lattice, strict=False)
    folded, start_xy, fold_xy = None, None, None
    if recip is not None and _spectrum_is_decisive(spec, recip, lattice):
        pitch, angle = _direct_from_reciprocal(recip, lattice)
    else:
        # a scene image (or a small crop): repeated scene content can outscore the lattice in
        # the spectrum; the micro-image borders decide between the spectral hypotheses
        pitch, angle, score, fold_xy = _lattice_by_fold(image, cfa, lattice)
        start_xy = fold_xy
        folded = (pitch, angle)
        # the fold measures the central region; where the spectrum has peaks on that lattice,
        # their least-squares fit is the start (as for a white image), the fold's otherwise
        g = np.linalg.inv(LensGrid(pitch, angle, (0.0, 0.0), lattice).basis()).T[0]
        peaks = _refine_reciprocal(spec, g, lattice, kmax=min(SCORE_BAND, 3.1 * np.linalg.norm(g)))
        p_spec, a_spec = _direct_from_reciprocal(peaks, lattice)
        step = LATTICES[lattice]
        if (_score(spec, peaks) > 0 and abs(p_spec / pitch - 1) < 0.002
                and abs((a_spec - angle + step / 2) % step - step / 2) < 0.002):
            pitch, angle = p_spec, a_spec
            start_xy = None   # and the phases of those peaks the offset
    if not PITCH_RANGE_PX[0] <= pitch <= PITCH_RANGE_PX[1]:
        raise CalibrationError(f"the lattice found has a pitch of {pitch:.2f} px, outside "
                               f"{PITCH_RANGE_PX[0]:g}-{PITCH_RANGE_PX[1]:g} px")
    flat = flatten(image, cfa=cfa, scale_px=max(FLAT_SCALE * pitch, 8.0))
    grid = LensGrid(pitch, angle, (0.0, 0.0), lattice, image_shape=(rows, cols))
    if start_xy is None:   # the phases of the fundamentals; a scene may have none: its fold
        start_xy = _phase_offset(flat, grid)
    grid = _reindexed(pitch, angle, start_xy, lattice, (rows, cols))

    idx, centres, refined = refine_centres(flat, grid)
    n_ref = int(refined.sum())
    if n_ref < MIN_LENSES:
        raise CalibrationError(f"only {n_ref} whole micro-images fit in the {cols} x {rows} px "
                               f"image (pitch {pitch:.1f} px); use a larger image")
    use = refined.copy()
    for _ in range(4):  # robust: drop lenses whose centroid is disturbed (dead pixels, scene)
        pitch, angle, offset = fit_lattice(idx[use], centres[use], lattice=lattice)
        fitted = LensGrid(pitch, angle, offset, lattice)
        resid = np.linalg.norm(centres - fitted.lattice_xy(idx[:, 0], idx[:, 1]), axis=1)
        sigma = 1.4826 * np.median(resid[refined])
        new_use = refined & (resid <= max(4.0 * sigma, 0.02))
        if np.array_equal(new_use, use):
            break
        use = new_use
    spread = np.sqrt(np.sum((centres[use] - centres[use].mean(axis=0)) ** 2))
    angle_se = np.sqrt(np.mean(resid[use] ** 2)) / max(spread, 1e-9)   # rad
    if folded is not None and angle_se > FOLD_ANGLE_PRECISION / min(max(rows, cols),
                                                                    FOLD_MAX_PX):
        # a scene with few lenses: its micro-images are not symmetric and their centres follow
        # the content, so the lattice fitted through them is less certain than the fold's; the
        # borders (the fold) give pitch, rotation and offset
        step = LATTICES[lattice]
        pitch, angle = folded[0], angle + (folded[1] - angle + step / 2) % step - step / 2
        basis = LensGrid(pitch, angle, (0.0, 0.0), lattice).basis()
        i, j = fitted.nearest_index(*fold_xy)
        offset = tuple(float(v) for v in np.asarray(fold_xy) - i * basis[0] - j * basis[1])
        fitted = LensGrid(pitch, angle, offset, lattice)
    grid = _reindexed(pitch, angle, offset, lattice, (rows, cols))
    # re-express indices relative to the reindexed lens (0, 0)
    di, dj = fitted.nearest_index(*grid.offset_xy)
    idx = idx - np.array([int(di), int(dj)])
    turns = int(np.rint((angle - grid.angle_rad) / LATTICES[lattice]))
    idx = _rotate_indices(idx, turns, lattice)
    ideal = grid.lattice_xy(idx[:, 0], idx[:, 1])
    resid_vec = centres - ideal
    resid = np.linalg.norm(resid_vec, axis=1)
    outliers = refined & ~use
    centres = np.where(outliers[:, None], ideal, centres)   # a disturbed lens keeps the lattice
    rms = float(np.sqrt(np.mean(resid[use] ** 2)))
    scene = rms > SCENE_RESIDUAL * pitch
    if scene:
        # a scene image: micro-image content is not symmetric, per-lens centroids only add
        # noise; the lattice (fitted over thousands of lenses) is the result
        centres = ideal
    report = CalibrationReport(
        lenses_total=len(idx), lenses_refined=n_ref, outliers=int(outliers.sum()),
        residual_rms_px=float(np.sqrt(np.mean(resid[use] ** 2))),
        residual_max_px=float(resid[use].max()), spectrum_score=float(score),
        centres_refined=not scene)
    if not refine:
        return grid, report
    return LensGrid(grid.pitch_px, grid.angle_rad, grid.offset_xy, lattice,
                    image_shape=(rows, cols), centres_xy=centres, indices=idx), report


def _rotate_indices(idx: np.ndarray, turns: int, lattice: str) -> np.ndarray:
    """Indices of the same lenses after the basis turned by ``turns`` lattice steps
    (b1' = R(-turns*step) b1 ...), i.e. the new basis is the old one rotated back."""
    i, j = idx[:, 0], idx[:, 1]
    for _ in range(turns % (6 if lattice == "hex" else 4)):
        # old basis rotated by -step becomes the new one: old b1 = new b2, old b2 = new b2 - new b1
        # (hex) / old b1 = new b2, old b2 = -new b1 (square). Then a lens i b1 + j b2 (old) is:
        if lattice == "hex":
            i, j = -j, i + j
        else:
            i, j = -j, i
    return np.stack([i, j], axis=1)


# ----------------------------------------------------------------------------------------------
# comparison and checks
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


def mean_micro_image(image: np.ndarray, centres: np.ndarray, *, half: int) -> np.ndarray:
    """Average of the micro-images around ``centres`` (K, 2), resampled bilinearly on a
    (2 half + 1)^2 grid centred on each centre: its symmetry centre is the grid's bias."""
    rows, cols = image.shape
    offs = np.arange(-half, half + 1, dtype=np.float32)
    acc = np.zeros((len(offs), len(offs)), np.float64)
    img = np.asarray(image, np.float32)
    keep = ((centres[:, 0] > half + 1) & (centres[:, 0] < cols - half - 2)
            & (centres[:, 1] > half + 1) & (centres[:, 1] < rows - half - 2))
    for x, y in centres[keep]:
        mapx = (x + offs)[None, :].repeat(len(offs), 0).astype(np.float32)
        mapy = (y + offs)[:, None].repeat(len(offs), 1).astype(np.float32)
        acc += cv2.remap(img, mapx, mapy, cv2.INTER_LINEAR)
    return acc / max(int(keep.sum()), 1)


def symmetry_centre(patch: np.ndarray, *, radius: float) -> tuple[float, float]:
    """Point-symmetry centre (dx, dy) of a patch relative to its middle pixel (px).

    Minimises sum over |r| < radius of (P(c + r) - P(c - r))^2 over sub-pixel c (bilinear
    resampling, Nelder-Mead)."""
    from scipy.optimize import minimize

    n = patch.shape[0]
    mid = (n - 1) / 2
    yy, xx = np.mgrid[0:n, 0:n].astype(np.float32) - np.float32(mid)
    inside = np.hypot(xx, yy) < radius
    p = patch.astype(np.float32)

    def cost(c):
        fwd = cv2.remap(p, (mid + c[0] + xx).astype(np.float32),
                        (mid + c[1] + yy).astype(np.float32), cv2.INTER_CUBIC)
        back = cv2.remap(p, (mid + c[0] - xx).astype(np.float32),
                         (mid + c[1] - yy).astype(np.float32), cv2.INTER_CUBIC)
        return float(np.sum((fwd - back)[inside] ** 2))

    res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-12, "maxiter": 400})
    return float(res.x[0]), float(res.x[1])

