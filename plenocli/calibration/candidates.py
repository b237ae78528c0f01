"""Lattice hypotheses: the peaks of the power spectrum, each read as a hexagonal and as a square
lattice, with every relative a peak could belong to (a harmonic or a sub-lattice).

The spectrum only proposes; it never decides. A white image shows the lattice as its strongest
peaks, but on a scene the parallax repeats content at a depth-dependent period close to the
pitch, a multi-focus array adds the sqrt(3) lattice of its lens types, and a harmonic can be
stronger than the fundamental. So every peak is taken as several hypotheses and
``plenocli.calibration.verify`` judges them all with one measure.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numba
import numpy as np
import scipy.fft
from scipy.optimize import minimize

from plenocli.model.lensgrid import LATTICES

PEAK_Z = 4.0          # a spectral peak stands this many robust sigma above its ring
# no micro-lens lattice is finer: a micro-image under 3 px across holds no image (the least
# --pitch takes, so every lattice found without a hint can be given as one); the halves, thirds
# and quarters of a lattice's relatives below it are the pixel grid's aliases, not lens lattices
MIN_LENS_PITCH_PX = 3.0
PEAKS_PER_SPECTRUM = 8
RING_SAMPLES = 512    # a ring's statistics come from 512-1023 of its bins (all if fewer)


@dataclass(frozen=True)
class Lattice:
    """A similarity lattice: kind ("hex" or "square"), nearest-neighbour distance (px) and the
    angle of its first basis vector (rad, from +x towards +y, reduced to one lattice period)."""

    kind: str
    pitch_px: float
    angle_rad: float

    def __post_init__(self):
        step = LATTICES[self.kind]
        object.__setattr__(self, "angle_rad", float(self.angle_rad % step))

    def basis(self) -> np.ndarray:
        """(2, 2) rows b1, b2 (px)."""
        a, step = self.angle_rad, LATTICES[self.kind]
        return self.pitch_px * np.array([[np.cos(a), np.sin(a)],
                                         [np.cos(a + step), np.sin(a + step)]])

    def scaled(self, factor: float, turn: float = 0.0) -> Lattice:
        return Lattice(self.kind, self.pitch_px * factor, self.angle_rad + turn)

    def same_as(self, other: Lattice, *, rel: float = 0.01, angle: float = 0.01) -> bool:
        if self.kind != other.kind or abs(self.pitch_px / other.pitch_px - 1) > rel:
            return False
        step = LATTICES[self.kind]
        return abs((self.angle_rad - other.angle_rad + step / 2) % step - step / 2) <= angle

    def relatives(self) -> list[Lattice]:
        """The lattices a spectral peak of this one could really belong to: twice and half the
        pitch, the index-3 (hex: sqrt(3), turned 30 deg) or index-2 (square: sqrt(2), turned
        45 deg) super- and sub-lattices, and the other kind at the same pitch (those of at
        least MIN_LENS_PITCH_PX)."""
        turn, root = (np.pi / 6, np.sqrt(3)) if self.kind == "hex" else (np.pi / 4, np.sqrt(2))
        other = "square" if self.kind == "hex" else "hex"
        return [lat for lat in (self.scaled(2), self.scaled(0.5), self.scaled(root, turn),
                                self.scaled(1 / root, turn),
                                Lattice(other, self.pitch_px, self.angle_rad))
                if lat.pitch_px >= MIN_LENS_PITCH_PX]

    def describe(self) -> str:
        """Pitch and angle, the angle the lattice's smallest turn from the x axis (a hex lattice
        at 59.99 deg is the one at -0.01 deg: two candidates shown side by side compare at a
        glance; a grid file keeps the angle its fit ended at)."""
        step = LATTICES[self.kind]
        turn = (self.angle_rad + step / 2) % step - step / 2
        return f"{self.kind} {self.pitch_px:.2f} px at {np.degrees(turn):.2f} deg"

    def climbed(self, score, *, step: float, evaluations: int, xatol: float,
                fatol: float) -> Lattice:
        """The local maximum of ``score(lattice)`` near this lattice: Nelder-Mead in (log
        pitch, angle) from a simplex of ``step`` on each axis."""
        def cost(p):
            return -score(Lattice(self.kind, self.pitch_px * np.exp(p[0]), self.angle_rad + p[1]))

        res = minimize(cost, np.zeros(2), method="Nelder-Mead",
                       options={"initial_simplex": [[0, 0], [step, 0], [0, step]],
                                "xatol": xatol, "fatol": fatol, "maxfev": evaluations})
        return Lattice(self.kind, self.pitch_px * np.exp(res.x[0]), self.angle_rad + res.x[1])


def distinct(lattices: list[Lattice], *, rel: float = 0.01, angle: float = 0.01
             ) -> list[Lattice]:
    """The first of each set of ``lattices`` that are the same lattice (``Lattice.same_as``
    with these tolerances against every one kept before it), in their order."""
    if not lattices:
        return []
    pitch = np.array([lat.pitch_px for lat in lattices])
    turn = np.array([lat.angle_rad for lat in lattices])
    step = np.array([LATTICES[lat.kind] for lat in lattices])
    keep = _first_of_each(pitch, turn, step, rel, angle)
    return [lat for lat, k in zip(lattices, keep, strict=True) if k]


@numba.njit(cache=True, nogil=True)
def _first_of_each(pitch, turn, step, rel, angle):  # pragma: no cover - compiled
    """Which lattices no earlier kept one equals by ``Lattice.same_as`` (the same arithmetic;
    the kind is told by its angle step)."""
    keep = np.zeros(pitch.shape[0], np.bool_)
    kept = np.empty(pitch.shape[0], np.int64)
    count = 0
    for i in range(pitch.shape[0]):
        same = False
        for q in range(count):
            k = kept[q]
            if step[k] != step[i] or abs(pitch[i] / pitch[k] - 1) > rel:
                continue
            half = step[i] / 2
            if abs((turn[i] - turn[k] + half) % step[i] - half) <= angle:
                same = True
                break
        if not same:
            keep[i] = True
            kept[count] = i
            count += 1
    return keep


def spectral_peaks(signal: np.ndarray, *, cfa: bool = False,
                   count: int = PEAKS_PER_SPECTRUM) -> list[np.ndarray]:
    """The strongest isolated peaks (fx, fy) cycles/px of the Hann-windowed power spectrum of
    ``signal`` (one of each +- pair), as z-scores against a robust background per ring of
    radius (a scene's 1/f spectrum, noise), sub-bin by a parabola in log magnitude."""
    rows, cols = signal.shape
    data = signal - np.float32(signal.mean())
    data *= np.hanning(rows).astype(np.float32)[:, None]
    data *= np.hanning(cols).astype(np.float32)[None, :]
    size = max(rows, cols)
    spec = scipy.fft.rfft2(data, s=(size, size), workers=1)
    logmag = np.abs(spec)
    del spec
    logmag += 1e-12
    np.log(logmag, out=logmag)
    z = _ring_zscore(logmag, _rings(size), 3.0 / min(rows, cols))
    if cfa:   # residual mosaic sits at the Nyquist corners
        fy = np.fft.fftfreq(size)[:, None]
        fx = np.fft.rfftfreq(size)[None, :]
        for nx, ny in ((0.5, 0.0), (0.0, 0.5), (0.5, 0.5), (0.5, -0.5)):
            z[np.hypot(fx - nx, fy - ny) <= 0.03] = -np.inf
    local = cv2.dilate(z, np.ones((5, 5), np.uint8))
    peaks = np.argwhere((z >= local) & (z > PEAK_Z))
    order = np.argsort(-z[peaks[:, 0], peaks[:, 1]])[:count]
    out = []
    for r, c in peaks[order]:
        if not 0 < c < logmag.shape[1] - 1:
            continue
        ox = _parabola(logmag[r, c - 1], logmag[r, c], logmag[r, c + 1])
        oy = _parabola(logmag[(r - 1) % size, c], logmag[r, c], logmag[(r + 1) % size, c])
        row = r if r < size // 2 else r - size
        out.append(np.array([(c + ox) / size, (row + oy) / size]))
    return out


def lattices_of_peak(g: np.ndarray, factor: float = 1.0) -> list[Lattice]:
    """The hex and square lattices whose first reciprocal ring holds the peak ``g`` (cycles per
    pixel of an image decimated by ``factor``), in pixels of the full image, with their
    relatives."""
    norm = float(np.hypot(*g))
    angle = float(np.arctan2(g[1], g[0]))
    first = [Lattice("hex", factor / (norm * np.sin(np.pi / 3)), angle + np.pi / 6),
             Lattice("square", factor / norm, angle)]
    return [lat for f in first for lat in [f, *f.relatives()]]


def lattices_of_lag(lag: np.ndarray, factor: float = 1.0) -> list[Lattice]:
    """The hex and square lattices with the nearest-neighbour vector ``lag`` (px of an image
    decimated by ``factor``), in pixels of the full image, with their relatives."""
    pitch = factor * float(np.hypot(*lag))
    angle = float(np.arctan2(lag[1], lag[0]))
    first = [Lattice("hex", pitch, angle), Lattice("square", pitch, angle)]
    return [lat for f in first for lat in [f, *f.relatives()]]


@dataclass(frozen=True)
class _Rings:
    """The radius (cycles/px) of every bin of a (size, size // 2 + 1) real spectrum, its ring
    of 4 bins, and the bins its statistics are taken from grouped by ring (``order``: every
    bin of a small ring, an even spread of RING_SAMPLES to twice that of a larger one) with
    where each ring starts there."""

    radius: np.ndarray
    ring: np.ndarray
    order: np.ndarray
    start: np.ndarray


@functools.lru_cache(maxsize=4)
def _rings(size: int) -> _Rings:
    """The ring geometry of a spectrum size (the views share a few sizes: kept, not redone)."""
    radius = np.hypot(np.fft.rfftfreq(size)[None, :], np.fft.fftfreq(size)[:, None])
    nring = size // 4 + 2
    ring = np.minimum(radius * (size / 4), nring - 1).astype(np.int16)
    # a stable sort of small integers is a radix sort; within a ring, bins in raster order
    order = np.argsort(ring.ravel(), kind="stable").astype(np.int32)
    counts = np.bincount(ring.ravel(), minlength=nring)
    start = np.concatenate([[0], np.cumsum(counts)])
    # every stride-th bin of a ring of thousands: the spread (median - 16th percentile) moves
    # by 4 % on average (22 % at most), which only shifts which weak peaks propose hypotheses
    stride = np.maximum(counts // RING_SAMPLES, 1)
    rank = np.arange(order.size) - np.repeat(start[:-1], counts)
    sample = order[rank % np.repeat(stride, counts) == 0]
    sample_start = np.concatenate([[0], np.cumsum(-(-counts // stride))])
    for a in (radius, ring, sample, sample_start):
        a.flags.writeable = False
    return _Rings(radius, ring, sample, sample_start)


def _ring_zscore(logmag: np.ndarray, rings: _Rings, min_radius: float) -> np.ndarray:
    """(logmag - median) / (median - 16th percentile) per ring of 4 bins, -inf up to
    ``min_radius`` (cycles/px): the peaks of a lattice are a minority of each ring and do not
    inflate it. Two order statistics per ring by partition: no full sort of the spectrum."""
    median, low = _ring_quantiles(logmag.ravel()[rings.order], rings.start)
    spread = np.maximum(median - low, 0.05)   # a flat field has no spread: no peak passes
    return _normalised(logmag, rings.ring, median.astype(np.float32),
                       spread.astype(np.float32), rings.radius, min_radius)


@numba.njit(cache=True, nogil=True)
def _normalised(logmag, ring, median, spread, radius, min_radius):  # pragma: no cover
    """(logmag - median[ring]) / spread[ring] in float32, -inf where radius <= min_radius
    (numba kernel: one pass, no gathered temporaries)."""
    z = np.empty_like(logmag)
    for r in range(logmag.shape[0]):
        for c in range(logmag.shape[1]):
            k = ring[r, c]
            z[r, c] = ((logmag[r, c] - median[k]) / spread[k] if radius[r, c] > min_radius
                       else -np.inf)
    return z


@numba.njit(cache=True, nogil=True)
def _ring_quantiles(grouped, start):  # pragma: no cover - compiled
    """The median and 16th percentile (the values of rank count // 2 and count * 16 // 100) of
    each ring of ``grouped`` (values grouped by ring, ring r at start[r]:start[r + 1]), by
    partition (numba kernel: one Python call, not one per ring)."""
    rings = start.shape[0] - 1
    median, low = np.zeros(rings), np.zeros(rings)
    for r in range(rings):
        count = start[r + 1] - start[r]
        if count == 0:
            continue
        mid, k_low = count // 2, (count * 16) // 100
        part = np.partition(grouped[start[r]:start[r + 1]], mid)
        median[r] = part[mid]
        low[r] = np.partition(part[:mid + 1], k_low)[k_low]   # the lower ranks are all there
    return median, low


def _parabola(a, b, c):
    """Vertex offset (-0.5 .. 0.5) of the parabola through three equally spaced samples
    (scalars or arrays); 0 where they do not form a maximum."""
    a, b, c = np.asarray(a, float), np.asarray(b, float), np.asarray(c, float)
    den = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den < 0, np.clip(0.5 * (a - c) / den, -0.5, 0.5), 0.0)
    return off if off.ndim else float(off)
