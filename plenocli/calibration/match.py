"""The third judge: neighbouring micro-images repeat each other's content at one shift.

A scene point at virtual depth g lies in neighbouring micro-images at offsets that differ by
their baseline times q = 1 / g (docs/depth.md): on the lens lattice, centred on the lens
centres, each micro-image matches its first ring at one q, far better than at any other
(``plenocli.depth.lenslet.lens_depth``: confidence 1 - best / median cost). Nothing else does:

- a lattice off in pitch or angle (so that the crop's corners move by half a pitch), or one
  centred on the holes or edge midpoints, cuts "micro-images" out of two or three real ones,
  whose parts repeat at different shifts or not at all;
- a relative (x2, /2, x sqrt(3), / sqrt(3)) pairs micro-images that are not neighbours, or
  parts of one micro-image with each other;
- a scene periodicity (a fabric, a grille) repeats at one period everywhere, but the parallax
  between micro-images follows their borders, not the scene's period.

It needs texture (a white image matches at every q and confirms nothing: then it refuses) and
nothing else: no dark gaps, no vignetting, no sharp borders. A devignetted ("processed")
frame, whose micro-images tile without gaps and whose only trace of the lattice is where the
content jumps between neighbours, is judged by it as well as any other (the R42 crop:
confidence 0.89 on its lattice, at most 0.80 elsewhere, docs/calibrate.md).

It is the costliest judge (a depth match per lattice and centre, about 0.1 s each on a
16 px-pitch view of a 1024 px crop), so it is asked last, only when a hint is given (a start
grid, whose pitch and angle it may keep, or a pitch, near which it measures them) and the
other two judges cannot vouch for a lattice.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from plenocli.calibration.candidates import Lattice
from plenocli.calibration.centres import lens_centre
from plenocli.calibration.flatten import border_signal, flatten
from plenocli.model.lensgrid import LATTICES, LensGrid

MATCH_SIDE_PX = 1024   # side of the central crop matched (full-image px)
MATCH_PITCH_PX = 16.0  # the crop is reduced to at most this pitch (g is scale-free)
RESIDUAL_RATIO = 2.0   # a rival's residual (1 - confidence) over the winner's, at least
MIN_CONFIDENCE = 0.5   # the winner's median lens confidence, at least
CORNER_SHARE = 0.05    # the kept pitch and angle place the image's corner lenses this close
#                        (share of a pitch) to where the match peaks
PEAK_REACH = 0.5       # the peak is placed from steps moving the corners by up to this share
#                        of a pitch (the detuned rivals' distance: the match has fallen there)
PEAK_SAMPLES = 4       # steps either side
G_RANGES = ((2.0, 12.0), (-12.0, -2.0))   # Keplerian and Galilean: the better one counts
PEAK_ERRORS = 2.0      # the peak and this many standard errors must lie within CORNER_SHARE
SCAN_SIDE = 8.0        # a pitch hint's rotation scan matches a central crop this many pitches
#                        wide (about 50 lenses: enough for a median, few for the cost)
SCAN_STEP = 0.5        # its rotation step moves that crop's corners by this share of a pitch
#                        (the match falls by half 0.4-0.5 pitch out, by 0.1-0.3 at 0.25)
SCAN_KEPT = 2          # lattices of the scan moved to their peak and judged, at most


@dataclass(frozen=True)
class MatchVerdict:
    """The lattice and lens centre confirmed (None: none), the median lens confidence there,
    the rivals with theirs, and why it refuses."""

    lattice: Lattice | None
    offset_xy: tuple[float, float] | None
    confidence: float
    rivals: tuple[tuple[str, float], ...] = field(default=())
    reason: str | None = None
    measured: bool = False     # pitch and angle measured (near a pitch hint), not given

    def to_dict(self) -> dict:
        return {"confidence": round(self.confidence, 4), "refused": self.reason,
                "rivals": [{"lattice": name, "confidence": round(c, 4)}
                           for name, c in self.rivals]}


def without_mosaic(image: np.ndarray, cfa: str | None) -> np.ndarray:
    """What the match judge looks at: ``image`` itself, or a Bayer mosaic's four phases each
    divided by its blurred self (their colour balance) and then smoothed by [1 2 1] / 4 along
    both axes, whose response is zero at the 2 px period: the mosaic's pattern, which repeats
    at every even shift and so matches on any lattice (the Raytrix scene simulator's RGGB
    frame: 0.61 on its lattice, 0.71 on the half-pitch relative), goes. A symmetric kernel
    moves nothing (a 2 x 2 box would move every lens centre by half a pixel)."""
    if not cfa:
        return image
    kernel = np.array([0.25, 0.5, 0.25], np.float32)
    return cv2.sepFilter2D(flatten(image, cfa=cfa), cv2.CV_32F, kernel, kernel,
                           borderType=cv2.BORDER_REFLECT)


class Matcher:
    """The central crop of an image, reduced per pitch, and the median lens confidence of a
    lattice with a given lens centre on it."""

    def __init__(self, image: np.ndarray):
        rows, cols = image.shape
        self.image_radius = float(np.hypot(rows, cols)) / 2
        side_r, side_c = min(rows, MATCH_SIDE_PX), min(cols, MATCH_SIDE_PX)
        self.r0, self.c0 = (rows - side_r) // 2, (cols - side_c) // 2
        self.crop = np.ascontiguousarray(image[self.r0:self.r0 + side_r,
                                               self.c0:self.c0 + side_c], np.float32)
        self.radius = float(np.hypot(side_r, side_c)) / 2
        self._views: dict[float, np.ndarray] = {}
        self.ranges = G_RANGES    # the g ranges searched: both signs until one is settled

    def _view(self, scale: float) -> np.ndarray:
        if scale not in self._views:
            self._views[scale] = self.crop if scale >= 1.0 else cv2.resize(
                self.crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        return self._views[scale]

    def confidence(self, lattice: Lattice, offset_xy: tuple[float, float]) -> float:
        """Median lens confidence of ``lattice`` with a lens at ``offset_xy`` (full-image
        px), the better of a Keplerian and a Galilean search; 0 where nothing can be matched."""
        found = self.lens_confidences(lattice, offset_xy)
        return float(np.median(found[1])) if len(found[1]) else 0.0

    def lens_confidences(self, lattice: Lattice, offset_xy: tuple[float, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
        """(indices (K, 2), confidence (K,)) of every lens of ``lattice`` in the crop (indices
        from the lens at ``offset_xy``), of the g range whose median is the best; none where
        nothing can be matched."""
        from plenocli.depth.lenslet import lens_depth, lens_table

        scale = round(min(1.0, MATCH_PITCH_PX / lattice.pitch_px), 4)
        view = self._view(scale)
        x = (offset_xy[0] - self.c0 + 0.5) * scale - 0.5
        y = (offset_xy[1] - self.r0 + 0.5) * scale - 0.5
        grid = LensGrid(lattice.pitch_px * scale, lattice.angle_rad, (x, y), lattice.kind,
                        image_shape=view.shape)
        best = (np.empty((0, 2), np.int64), np.empty(0))
        for bounds in self.ranges:
            try:
                found = lens_depth(view, grid, g_range=bounds)
            except ValueError:   # too few or too small micro-images on this lattice
                continue
            if not len(best[1]) or np.median(found.confidence) > np.median(best[1]):
                best = (lens_table(grid, view.shape)[0], found.confidence)
        return best

    def settle_sign(self, lattice: Lattice, offset_xy: tuple[float, float]) -> None:
        """Search only the sign of g (Keplerian or Galilean: the camera's, not a
        hypothesis's) that matches best on ``lattice`` from now on: halves every match."""
        scores = []
        for bounds in G_RANGES:
            self.ranges = (bounds,)
            scores.append(self.confidence(lattice, offset_xy))
        self.ranges = (G_RANGES[int(np.argmax(scores))],)


def symmetry_points(lattice: Lattice, centre: tuple[float, float]) -> list[tuple[str, tuple]]:
    """The points of a lattice cell that could be lens centres, from one of them: the point
    itself, and (hex) the two triangle centres and three edge midpoints, (square) the cell
    centre and two edge midpoints."""
    b1, b2 = lattice.basis()
    shifts = ({"": (0, 0), "hole": (1 / 3, 1 / 3), "hole'": (2 / 3, 2 / 3), "edge": (0.5, 0),
               "edge'": (0, 0.5), "edge''": (0.5, 0.5)} if lattice.kind == "hex" else
              {"": (0, 0), "hole": (0.5, 0.5), "edge": (0.5, 0), "edge'": (0, 0.5)})
    return [(name, tuple(float(v) for v in np.asarray(centre) + a * b1 + b * b2))
            for name, (a, b) in shifts.items()]


def _best_point(matcher: Matcher, lattice: Lattice, centre) -> list[tuple[str, tuple, float]]:
    """(name, offset, confidence) of each symmetry point, best first."""
    scored = [(name, xy, matcher.confidence(lattice, xy))
              for name, xy in symmetry_points(lattice, centre)]
    return sorted(scored, key=lambda t: -t[2])


def match_judge(image: np.ndarray, lattice: Lattice, others: list[Lattice], *,
                matcher: Matcher | None = None) -> MatchVerdict:
    """Whether the micro-images of ``image`` repeat each other's content on ``lattice`` (a
    start grid's, pitch and angle as given) and at which of its symmetry points the lenses
    are centred; refused unless that beats every other symmetry point, the lattice's
    relatives, its copies detuned so that the image's corners move by half a pitch, and
    ``others`` (unrelated lattices the image proposes) by RESIDUAL_RATIO in residual
    (1 - confidence), and unless the match peaks at the start's pitch and angle (its corner
    lenses within CORNER_SHARE of a pitch: a kept pitch must be as good as a measured one)."""
    matcher = matcher or Matcher(image)
    matcher.ranges = G_RANGES
    offset, confidence, rivals = _centred(matcher, lattice)
    matcher.settle_sign(lattice, offset)
    turn, root = (np.pi / 6, np.sqrt(3)) if lattice.kind == "hex" else (np.pi / 4, np.sqrt(2))
    for relative in (lattice.scaled(2), lattice.scaled(0.5), lattice.scaled(root, turn),
                     lattice.scaled(1 / root, turn)):   # the lens is a lattice point of each
        rivals.append((relative.describe(), matcher.confidence(relative, offset)))
    for other in others[:3]:
        rivals.append((other.describe(), _best_point(matcher, other, offset)[0][2]))
    shift = 0.5 * lattice.pitch_px / matcher.image_radius   # the image's corners move by half
    for detuned in (lattice.scaled(1 - shift), lattice.scaled(1 + shift),   # a lens (not only
                    lattice.scaled(1.0, -shift), lattice.scaled(1.0, shift)):   # the crop's)
        rivals.append((f"{detuned.describe()} (detuned)", matcher.confidence(detuned, offset)))
    rivals.sort(key=lambda t: -t[1])
    reason = None
    if confidence < MIN_CONFIDENCE:
        reason = (f"its micro-images do not repeat each other's content (median confidence "
                  f"{confidence:.2f})")
    elif 1 - rivals[0][1] < RESIDUAL_RATIO * (1 - confidence):
        reason = (f"its micro-images repeat each other's content (confidence {confidence:.2f}), "
                  f"but nearly as well on {rivals[0][0]} ({rivals[0][1]:.2f})")
    else:
        reason = _off_peak(matcher, lattice, offset, confidence)
    if reason:
        return MatchVerdict(None, None, confidence, tuple(rivals[:3]), reason)
    return MatchVerdict(lattice, offset, confidence, tuple(rivals[:3]))


def _centred(matcher: Matcher, lattice: Lattice) -> tuple[tuple, float, list]:
    """The lens centre of ``lattice`` among the symmetry points of the crop's mean border
    micro-image (the point nearest the crop's middle), its confidence, and the other points
    as rivals."""
    flat = flatten(matcher.crop, scale_px=max(2 * lattice.pitch_px, 16.0))
    rows, cols = flat.shape
    middle = LensGrid(lattice.pitch_px, lattice.angle_rad, ((cols - 1) / 2, (rows - 1) / 2),
                      lattice.kind)
    x, y = lens_centre(border_signal(flat), middle).offset_xy
    points = _best_point(matcher, lattice, (x + matcher.c0, y + matcher.r0))
    name, offset, confidence = points[0]
    rivals = [(f"{lattice.describe()} centred on its {n}", c) for n, _, c in points[1:]]
    return offset, confidence, rivals


def _vertices(matcher: Matcher, lattice: Lattice, offset, confidence: float, *,
              split: bool = True) -> tuple[float, float, float, tuple[float, float]]:
    """Where the match peaks around ``lattice``: per axis (relative pitch change, angle change
    in rad) the midpoint of the two points where the confidence falls through half its drop
    (peak to the higher of the two ends), from steps that move the image's corners by up to
    PEAK_REACH of a pitch either side; inf where it does not fall clearly on both sides (a
    lattice far off the peak, or a flat match). The top of the curve is flat over about
    two thirds of a pitch at the corners and may lean, so a parabola through it follows the
    lean; the falls are steep and symmetric about the lattice. Also the step that moves the
    corners by CORNER_SHARE of a pitch, and per axis the standard error of the midpoint
    (:func:`_split_error`; NaN unless ``split``)."""
    step = CORNER_SHARE * lattice.pitch_px / matcher.image_radius
    at = np.linspace(-1.0, 1.0, 2 * PEAK_SAMPLES + 1) * PEAK_REACH / CORNER_SHARE * step
    out, errors = [], []
    for move in (lambda d: lattice.scaled(1 + d), lambda d: lattice.scaled(1.0, d)):
        seen: dict[float, tuple] = {}

        def along(d, group=None, move=move, seen=seen):
            if d == 0 and group is None:
                return confidence
            if d not in seen:
                seen[d] = matcher.lens_confidences(move(d), offset)
            index, values = seen[d]
            if group is not None:
                values = values[_group_of(index) == group]
            return float(np.median(values)) if len(values) else 0.0

        out.append(_half_drop_midpoint(along, at, [along(d) for d in at]))
        errors.append(_split_error(along, at) if split else float("nan"))
    return out[0], out[1], step, (errors[0], errors[1])


SPLIT = 4   # lens groups (the cosets of the index-4 sub-lattice) whose peaks must agree


def _group_of(index: np.ndarray) -> np.ndarray:
    """The coset (0-3) of each lens index (i, j) in the index-4 sub-lattice: four groups
    spread alike over the image, with the same reach to its corners."""
    return 2 * (index[:, 0] % 2) + index[:, 1] % 2


def _split_error(along, at: np.ndarray) -> float:
    """Standard error of the peak's midpoint along one axis, from the spread of the
    midpoints each quarter of the lenses (``_group_of``) places on its own: each holds a
    quarter of the evidence, so the whole's error is their standard deviation / 2; inf when
    some quarter shows no peak."""
    parts = []
    for group in range(SPLIT):
        def one(d, group=group):
            return along(d, group)
        parts.append(_half_drop_midpoint(one, at, [one(d) for d in at]))
    if not np.all(np.isfinite(parts)):
        return float("inf")
    return float(np.std(parts, ddof=1) / np.sqrt(SPLIT))


def _half_drop_midpoint(confidence, at: np.ndarray, values: list[float]) -> float:
    """The midpoint of the half-drop crossings of a sampled peak (each placed between its two
    samples by one more sample and a straight line); inf unless both ends lie below the peak by
    RESIDUAL_RATIO in residual (1 - confidence), as the detuned rivals must (then +-inf: the
    sign of the end where it stays high)."""
    values = list(values)
    top = int(np.argmax(values))
    peak, end = values[top], max(values[0], values[-1])
    if end >= peak or not 1 - end >= RESIDUAL_RATIO * (1 - peak):   # signed: where it stays high
        return float(np.copysign(np.inf, values[-1] - values[0]))
    level = (peak + end) / 2
    sides = []
    for way in (-1, 1):
        i = top
        while values[i + way] >= level:
            i += way
        near, far = (at[i], values[i]), (at[i + way], values[i + way])
        mid = (near[0] + far[0]) / 2
        value = confidence(mid)
        near, far = ((mid, value), far) if value >= level else (near, (mid, value))
        sides.append(near[0] + (far[0] - near[0]) * (near[1] - level) / (near[1] - far[1]))
    return float(np.mean(sides))


def _off_peak(matcher: Matcher, lattice: Lattice, offset, confidence: float) -> str | None:
    """Why the match does not peak at the lattice's pitch and angle, or None: a vertex of
    :func:`_vertices` beyond CORNER_SHARE of a pitch at the corners, or one that the match
    does not pin down that well (the vertex and PEAK_ERRORS standard errors beyond it)."""
    pitch, angle, step, errors = _vertices(matcher, lattice, offset, confidence)
    moves = (("pitch", pitch, errors[0], "%", 100.0), ("rotation", angle, errors[1], "deg",
                                                     180 / np.pi))
    said = f"its micro-images repeat each other's content (confidence {confidence:.2f})"
    for what, vertex, _, unit, per in moves:
        if not abs(vertex) <= step:
            where = (f"{vertex * per:+.2f} {unit} from the given one" if np.isfinite(vertex)
                     else "nowhere near the given one")
            return f"{said}, best at a {what} {where}"
    for what, vertex, error, unit, per in moves:
        if not abs(vertex) + PEAK_ERRORS * error <= step:
            corners = (abs(vertex) + PEAK_ERRORS * error) / step * CORNER_SHARE
            return (f"{said}, but the match does not pin its {what} down: its peak lies "
                    f"{vertex * per:+.2f} +- {error * per:.2f} {unit} away (the spread of "
                    f"the peaks of the four quarters of the lenses), so the corner lenses "
                    f"may lie {corners:.2f} pitch off (the tolerance: {CORNER_SHARE:g})")
    return None


def match_measure(image: np.ndarray, pitch_hint: float, near: list[Lattice],
                  others: list[Lattice]) -> MatchVerdict:
    """The match judge where only a pitch is hinted: every rotation of both lattice kinds at
    the hint, and the hypotheses ``near`` it, scored on a small central crop
    (:func:`_scan`); the best that repeat their neighbours' content there (MIN_CONFIDENCE)
    are moved to where the match peaks on crops twice as wide each time (:func:`_to_peak`),
    then judged as a start would be (:func:`match_judge`); the first confirmed, else why
    none is."""
    scored = _scan(image, pitch_hint, near)
    if not scored or scored[0][1] < MIN_CONFIDENCE:
        best = (f" (best {scored[0][0].describe()}: median confidence {scored[0][1]:.2f})"
                if scored else "")
        return MatchVerdict(None, None, scored[0][1] if scored else 0.0, reason=(
            "on no lattice of either kind near it, at any rotation, do the micro-images repeat "
            f"each other's content{best}"))
    matcher, first = Matcher(image), None
    for lattice, _ in [t for t in scored if t[1] >= MIN_CONFIDENCE][:SCAN_KEPT]:
        lattice, ranges = _to_peak(image, lattice)
        matcher.ranges = ranges
        found = match_judge(image, lattice, others, matcher=matcher)
        if found.lattice is not None:
            return replace(found, measured=True)
        first = first or replace(found, reason=f"on {lattice.describe()} {found.reason}")
    return first


def _crop(image: np.ndarray, side: int) -> np.ndarray:
    rows, cols = image.shape
    r0, c0 = max(0, (rows - side) // 2), max(0, (cols - side) // 2)
    return image[r0:r0 + side, c0:c0 + side]


def _scan(image: np.ndarray, pitch: float, near: list[Lattice]) -> list[tuple[Lattice, float]]:
    """(lattice, median confidence) on a central crop SCAN_SIDE pitches wide, best first: the
    best rotation of each kind at ``pitch`` (steps that move the crop's corners by SCAN_STEP of
    a pitch: within the match's peak, which falls by half only half a pitch out) and each of
    ``near``. A small crop is what makes the scan affordable: its corners move little, so few
    rotations cover a lattice period, and few lenses are matched per rotation."""
    matcher = Matcher(_crop(image, int(max(SCAN_SIDE * pitch, 64))))
    step = SCAN_STEP * pitch / matcher.image_radius
    scored = []
    for kind, period in LATTICES.items():
        count = int(np.ceil(period / step))
        tried = [(lat, _centred(matcher, lat)[1]) for lat in
                 (Lattice(kind, pitch, turn) for turn in np.arange(count) * period / count)]
        scored.append(max(tried, key=lambda t: t[1]))
    scored += [(lat, _centred(matcher, lat)[1]) for lat in near[:3]]
    return sorted(scored, key=lambda t: -t[1])


def _to_peak(image: np.ndarray, lattice: Lattice) -> tuple[Lattice, tuple]:
    """``lattice`` moved to where the match peaks (pitch and angle to :func:`_vertices`;
    where the peak lies beyond their reach, half of it towards the higher end, and once
    again) on central crops each about twice as wide as the one before, from the scan's to
    the whole image: each crop's peak lies within the next one's reach. Also the g range
    settled."""
    sides, side = [max(image.shape)], max(image.shape) / 2
    while side > 1.5 * max(SCAN_SIDE * lattice.pitch_px, 64):   # not the scan's crop again
        sides.insert(0, side)
        side /= 2
    for side in sides:
        matcher = Matcher(_crop(image, int(side)))
        for _ in range(2):
            offset, confidence, _ = _centred(matcher, lattice)
            matcher.settle_sign(lattice, offset)
            pitch, angle, step, _ = _vertices(matcher, lattice, offset, confidence,
                                              split=False)
            half = PEAK_REACH / CORNER_SHARE * step / 2   # towards a peak beyond the reach
            pitch_move, angle_move = (float(np.clip(v, -half, half)) if np.isinf(v) else v
                                      for v in (pitch, angle))
            lattice = lattice.scaled(1 + pitch_move, angle_move)
            if np.isfinite(pitch) and np.isfinite(angle):
                break
    return lattice, matcher.ranges
