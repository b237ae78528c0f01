"""The lattice search: views of the image at a few decimations (so every pitch from 6 to 100 px
is seen with 10-20 px per lens), hypotheses from their spectra, each judged by the border
autocorrelation of the view that suits its pitch."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import cv2
import numba
import numpy as np

from plenocli.calibration.candidates import (
    Lattice,
    distinct,
    lattices_of_lag,
    lattices_of_peak,
    spectral_peaks,
)
from plenocli.calibration.fit import lattice_from_lags
from plenocli.calibration.flatten import border_signal, decimate, flatten
from plenocli.calibration.verify import Autocorrelation, Verdict, control_contrast, judge, refine

PITCH_RANGE_PX = (5.5, 110.0)   # searched; the documented range is 6-100 px
VIEW_PX = 1024                  # side of the central crop each view looks at
VIEW_FLAT_PX = 24.0             # flattening blur of a view (px of the view)
MIN_VIEW_PITCH = 10.0           # px per lens in the view that judges a pitch
REFINED = 4                     # hypotheses refined per search (and the best of each kind)


@dataclass(frozen=True)
class View:
    """The central crop of the image decimated by ``factor``: the autocorrelation of its
    flattened intensity and border signal, and the lattices its spectra and nearest
    autocorrelation peaks suggest (px of the full image)."""

    factor: int
    acf: Autocorrelation
    suggested: tuple[Lattice, ...]
    borders: dict = field(default_factory=dict, compare=False, repr=False)   # border_lattice's
    flat: np.ndarray | None = field(default=None, compare=False, repr=False)  # the crop, flat


def views(image: np.ndarray, cfa: str | None) -> dict[int, View]:
    """One view per decimation 1, 2, 4, 8 that still holds a useful crop (built side by side:
    the FFTs, filters and kernels they spend their time in release the GIL)."""
    factors = [f for f in (1, 2, 4, 8) if f == 1 or min(image.shape) // f >= 160]
    coarser = [*factors[1:], None]
    # numba's thread count is the process's budget (one in a batch worker); a view calls no
    # parallel numba kernel (numba's workqueue layer refuses parallel launches from threads)
    with ThreadPoolExecutor(max_workers=min(len(factors), numba.get_num_threads())) as pool:
        built = pool.map(lambda f, c: _view(image, cfa, f, c), factors, coarser)
        return dict(zip(factors, built, strict=True))


def _view(image: np.ndarray, cfa: str | None, factor: int, coarser: int | None) -> View:
    rows, cols = image.shape[0] // factor, image.shape[1] // factor
    # crop first (at full resolution), then decimate: an even factor averages the mosaic
    side_r, side_c = min(rows, VIEW_PX) * factor, min(cols, VIEW_PX) * factor
    r0, c0 = (image.shape[0] - side_r) // 2, (image.shape[1] - side_c) // 2
    r0, c0 = r0 - r0 % 2, c0 - c0 % 2
    crop = decimate(image[r0:r0 + side_r, c0:c0 + side_c], factor)
    flat = flatten(crop, cfa=cfa if factor == 1 else None, scale_px=VIEW_FLAT_PX)
    if cfa and factor == 1:   # what is left of the mosaic beats with small pitches
        flat = cv2.blur(flat, (2, 2))
    border = border_signal(flat)
    # view_for judges here the pitches with less than MIN_VIEW_PITCH px per lens in the
    # next, coarser view (the coarsest takes every wider one)
    widest = None if coarser is None else MIN_VIEW_PITCH * coarser / factor
    acf = Autocorrelation((flat, border), factor, widest)
    suggested = [lat for signal in (flat, border)
                 for g in spectral_peaks(signal, cfa=bool(cfa) and factor == 1)
                 for lat in lattices_of_peak(g, factor)]
    suggested += [lat for v in acf_peaks(acf.acf) for lat in lattices_of_lag(v, factor)]
    return View(factor, acf, tuple(suggested), flat=flat)


def view_for(lattice: Lattice, all_views: dict[int, View]) -> View:
    """The most decimated view that still has MIN_VIEW_PITCH px per lens (the longest lags in
    pitches)."""
    best = min(all_views)
    for factor in sorted(all_views):
        if lattice.pitch_px / factor >= MIN_VIEW_PITCH:
            best = factor
    return all_views[best]


def hypotheses(all_views: dict[int, View], *, pitch_hint: float | None) -> list[Lattice]:
    """Every lattice a spectral peak of a view suggests (both kinds, with relatives), inside
    the pitch range (or within 15 % of the hint)."""
    lo, hi = PITCH_RANGE_PX
    if pitch_hint is not None:
        lo, hi = pitch_hint / 1.15, pitch_hint * 1.15
    return distinct([lat for view in all_views.values() for lat in view.suggested
                     if lo <= lat.pitch_px <= hi])


def acf_peaks(acf: np.ndarray, *, count: int = 6) -> list[np.ndarray]:
    """The strongest local maxima (x, y) of an autocorrelation at lags of 4-24 px (half
    plane): nearest-neighbour vectors of the lattice when the spectrum is crowded by scene
    peaks."""
    cy, cx = acf.shape[0] // 2, acf.shape[1] // 2
    win = acf[cy - 25:cy + 26, cx - 25:cx + 26]
    local = cv2.dilate(win, np.ones((5, 5), np.uint8))
    dy, dx = np.mgrid[-25:26, -25:26]
    lag = np.hypot(dx, dy)
    keep = (win >= local) & (lag >= 4) & (lag <= 24) & ((dy > 0) | ((dy == 0) & (dx > 0)))
    order = np.argsort(-win[keep])[:count]
    return [np.array([x, y], float) for x, y in zip(dx[keep][order], dy[keep][order],
                                                    strict=True)]


def find_lattice(all_views: dict[int, View], hyps: list[Lattice]) -> Verdict:
    """Score every hypothesis over near lags, refine the best few (per kind) and judge them."""
    if not hyps:
        return Verdict(Lattice("hex", 10.0, 0.0), -np.inf)
    first = [(lat, view_for(lat, all_views).acf.contrast(lat, near=1.5, far=6.0))
             for lat in hyps]
    first.sort(key=lambda t: -t[1])
    chosen: list[Lattice] = []
    for lat, c in first:   # one per neighbourhood: a scene repetition comes in many variants
        if c > 0 and len(chosen) < REFINED and not any(
                lat.same_as(other, rel=0.06, angle=0.06) for other in chosen):
            chosen.append(lat)
    for kind in ("hex", "square"):   # the best of each kind, to say which kind fits
        if not any(lat.kind == kind for lat in chosen):
            chosen += [lat for lat, c in first if c > 0 and lat.kind == kind][:1]
    if not chosen:   # no hypothesis has its points above its holes even over near lags
        return Verdict(first[0][0], first[0][1], considered=tuple(first[:REFINED]))
    return judged(_refined_all(chosen, all_views), all_views)


def _refined_all(lattices: list[Lattice], all_views: dict[int, View]
                 ) -> list[tuple[Lattice, float]]:
    """``refined`` of each lattice, side by side: each is independent, and the contrast and
    peak kernels it spends its time in release the GIL (numba's thread count is the budget,
    as for the views). The costliest start first: those with the most lags in their view's
    reach (a hex cell is sqrt(3) / 2 of a square one)."""
    def lags(lat: Lattice) -> float:
        view = view_for(lat, all_views)
        cell = np.sqrt(3) / 2 if lat.kind == "hex" else 1.0
        return (view.acf.reach * view.factor / lat.pitch_px) ** 2 / cell

    with ThreadPoolExecutor(max_workers=min(len(lattices), numba.get_num_threads())) as pool:
        started = {k: pool.submit(refined, lattices[k], all_views)
                   for k in sorted(range(len(lattices)), key=lambda k: -lags(lattices[k]))}
        return [started[k].result() for k in range(len(lattices))]


def refined(lattice: Lattice, all_views: dict[int, View]) -> tuple[Lattice, float]:
    """A hypothesis at its local contrast maximum, moved onto its far border peaks."""
    return _measured(*refine(lattice, view_for(lattice, all_views).acf), all_views)


def judged(scored: list[tuple[Lattice, float]], all_views: dict[int, View]) -> Verdict:
    """The verdict on refined hypotheses: the winner checked against its relatives and
    rivals, measured again until it holds still, with its detuned control."""
    acf_for = lambda lat: view_for(lat, all_views).acf   # noqa: E731
    verdict = judge(scored, acf_for)
    for _ in range(3):   # a winner reached through a relative is measured and judged again
        lat, c = _measured(verdict.lattice, verdict.contrast, all_views)
        if lat.same_as(verdict.lattice, rel=2e-4, angle=2e-4):
            break
        verdict = judge(scored, acf_for, leader=(lat, c))
    else:   # the far border peaks do not hold still on the winner: no stable lattice
        verdict = replace(verdict, undecided=True)
    control = control_contrast(verdict.lattice, view_for(verdict.lattice, all_views).acf)
    return replace(verdict, control=control, considered=tuple(scored))


def _measured(lattice: Lattice, contrast: float, all_views) -> tuple[Lattice, float]:
    """The hypothesis moved onto its far border-autocorrelation peaks (relatives are then
    tested at exact multiples), with its contrast there; unchanged when the peaks do not
    support it (no peaks, or more than 3 % away)."""
    precise = border_lattice(lattice, all_views)
    if not (np.isfinite(precise.pitch_err_px)
            and precise.lattice.same_as(lattice, rel=0.03, angle=0.03)):
        return lattice, contrast
    return precise.lattice, view_for(precise.lattice, all_views).acf.contrast(precise.lattice)


@dataclass(frozen=True)
class BorderLattice:
    """The lattice measured from the far autocorrelation peaks of the border signal, with its
    uncertainty (the larger of the fit's standard error and the spread between two starts)."""

    lattice: Lattice
    pitch_err_px: float
    angle_err_rad: float


def border_lattice(lattice: Lattice, all_views: dict[int, View]) -> BorderLattice:
    """Pitch and angle from the far border-autocorrelation peaks, iterated from two starts
    0.3 % apart (the peak centroids lean towards the prediction; converged, they agree unless
    the frame is too small for its scene to have stopped repeating). Kept per view: a
    search measures its winner again, and so does the calibration."""
    view = view_for(lattice, all_views)
    if lattice not in view.borders:
        view.borders[lattice] = _border_lattice(lattice, view.acf)
    return view.borders[lattice]


def _border_lattice(lattice: Lattice, acf: Autocorrelation) -> BorderLattice:
    ends = []
    for start in (lattice.scaled(0.997), lattice.scaled(1.003)):
        current, se = start, (np.inf, np.inf)
        for _ in range(4):
            lags, idx, height = acf.peak_lags(current)
            if len(lags) < 6 or not height.sum() > 0:
                return BorderLattice(lattice, np.inf, np.inf)
            pitch, angle, se = lattice_from_lags(lags, idx, height, lattice=lattice.kind)
            if not pitch > 0:
                return BorderLattice(lattice, np.inf, np.inf)
            moved = Lattice(lattice.kind, pitch, angle)
            still = moved.same_as(current, rel=1e-5, angle=1e-5)
            current = moved
            if still:   # the peaks no longer move
                break
        ends.append((current, se))
    (a, se_a), (b, se_b) = ends
    step = np.pi / 3 if lattice.kind == "hex" else np.pi / 2
    dangle = abs((a.angle_rad - b.angle_rad + step / 2) % step - step / 2)
    mean = Lattice(lattice.kind, (a.pitch_px + b.pitch_px) / 2, a.angle_rad)
    return BorderLattice(mean, max(abs(a.pitch_px - b.pitch_px), se_a[0], se_b[0]),
                         max(dangle, se_a[1], se_b[1]))
