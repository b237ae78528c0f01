"""Depth of a focused-plenoptic (lenslet) capture from the disparity between micro-images.

A scene point at virtual depth g (the refocus parameter of Eq. 3) is seen by every micro-image
whose footprint covers it. In micro-image i it lies at offset u from the centre c_i; in the
neighbouring micro-image j at u - (c_j - c_i) / g. So the content of neighbouring micro-images
is shifted by the baseline c_j - c_i times q = 1 / g, and q is found by matching each
micro-image against its neighbours (first ring at one pitch, second ring at sqrt(3) pitch on a
hex array, sqrt(2) on a square one):

1. The micro-image vignetting is measured from the frame itself: the mean of all micro-images
   by offset from their centre (textures average out over thousands of lenses). Dividing by it
   flattens every micro-image, and where it is below half its peak the micro-image is not used.
2. Coarse search: the sum of squared differences against the first ring at candidate q,
   0.5 px of shift apart, over the bounds given (``g_range``).
3. Refinement: Gauss-Newton steps on q against both rings together (sub-pixel, unbiased by the
   candidate spacing).
4. Confidence per lens: 1 - (best cost / median cost) of the coarse curve: near 1 for a sharp,
   unique minimum, near 0 where every q fits alike (no texture) or where nothing fits.
5. Each lens's g is spread over its footprint on the refocused grid (the disc of radius
   s |g| r around s c_i where its pixels land, r the usable micro-image radius), weighted by a
   tent times the confidence: the map lies on the grid of ``refocus --s S``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from plenocli.depth import kernels as kn
from plenocli.depth.directions import direction_medians
from plenocli.depth.nearlimit import drop_alone, measurable_q
from plenocli.model.lensgrid import LensGrid

RINGS = {"hex": ([(1, 0), (0, 1), (-1, 1), (-1, 0), (0, -1), (1, -1)],
                 [(1, 1), (-1, 2), (-2, 1), (-1, -1), (1, -2), (2, -1)]),
         "square": ([(1, 0), (0, 1), (-1, 0), (0, -1)],
                    [(1, 1), (-1, 1), (-1, -1), (1, -1)])}
SHIFT_STEP_PX = 1.0   # candidate spacing of the coarse search, in shift along one pitch
REFINE_STEPS = 3
COARSE_STRIDE = 4     # the coarse search looks at every 4th pixel, the refinement every 2nd
REFINE_STRIDE = 2
PROFILE_DEGREE = 6
PROFILE_TERMS = 16    # even monomials of degree <= 6
RIM_BINS = 3          # 1.5 px (0.5 px bins) of rim left out of the usable disc
CLEAR_MATCH = 0.5     # median lens confidence above which the sign of g is not questioned
SIGN_MARGIN = 0.2     # the other sign must beat this range's median confidence by this much
RENDER_REACH = 1.0    # a lens's g reaches this many lens spacings on the output grid
USABLE_LEVEL = 0.5    # micro-image pixels below this share of the profile's peak are unused
MIN_JUDGED = 10       # lenses in and out of their type's range needed to judge the ranges
OVERLAP_RISE = 0.05   # a mean micro-image this much brighter than nearer its centre: overlap
MIN_SHIFT_PX = 0.5    # smallest shift between neighbouring micro-images that measures a g


@dataclass(frozen=True)
class LensDepth:
    """Per-lens estimate: centres (K, 2), g (K,) (NaN: none), confidence (K,) in 0..1, the
    usable micro-image radius (px), and whether lens-type depth ranges were used."""

    centres: np.ndarray
    g: np.ndarray
    confidence: np.ndarray
    radius_px: float
    ranges_used: bool | None = None  # lens-type ranges given: whether the frame bore them out
    g_by_direction: np.ndarray | None = None  # median g along each lattice direction alone


@dataclass(frozen=True)
class DepthMap:
    """A depth map on the refocused grid: g and confidence (rows_out, cols_out) float32."""

    g: np.ndarray
    confidence: np.ndarray
    lenses: LensDepth


def sensor_grey(pages: np.ndarray, *, mosaic: bool) -> np.ndarray:
    """One grey sensor image (rows, cols) float32 of (P, rows, cols) pages: their mean; a Bayer
    mosaic through the 3 x 3 binomial, which weighs R, G, B alike (1/4, 1/2, 1/4) at every
    pixel and shifts nothing."""
    import cv2

    grey = np.asarray(pages, np.float32).mean(axis=0)
    if mosaic:
        taps = np.array([0.25, 0.5, 0.25], np.float32)
        grey = cv2.sepFilter2D(grey, -1, taps, taps, borderType=cv2.BORDER_REFLECT)
    return grey


def lens_table(grid: LensGrid, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(indices (K, 2), centres (K, 2)) of the lenses of ``grid`` whose centre lies in a
    (rows, cols) image: refined centres where the grid has them."""
    if grid.centres_xy is None:
        grid = replace(grid, image_shape=tuple(shape))
    idx, xy = grid.lens_centres()
    inside = ((xy[:, 0] >= 0) & (xy[:, 0] <= shape[1] - 1)
              & (xy[:, 1] >= 0) & (xy[:, 1] <= shape[0] - 1) & np.isfinite(xy).all(axis=1))
    return np.asarray(idx, np.int64)[inside], np.asarray(xy, float)[inside]


def neighbours(indices: np.ndarray, offsets: list[tuple[int, int]]) -> np.ndarray:
    """(K, len(offsets)) index of each lens's neighbour at each lattice offset, -1 if absent."""
    lo = indices.min(axis=0) - 3
    size = indices.max(axis=0) - lo + 4
    table = np.full(size, -1, np.int64)
    table[indices[:, 0] - lo[0], indices[:, 1] - lo[1]] = np.arange(len(indices))
    out = np.full((len(indices), len(offsets)), -1, np.int64)
    for m, (di, dj) in enumerate(offsets):
        out[:, m] = table[indices[:, 0] - lo[0] + di, indices[:, 1] - lo[1] + dj]
    return out


def micro_profile(frame: np.ndarray, centres: np.ndarray, pitch: float
                  ) -> tuple[np.ndarray, np.ndarray, int, float]:
    """The mean micro-image by offset (0.5 px bins): NaN where unusable, and filled; its
    half-size in pixels and the usable radius."""
    from scipy import ndimage

    radius = 0.5 * pitch
    half = int(math.ceil(radius)) + 1
    sums, counts = kn.profile_sums(frame, centres[:, 0].copy(), centres[:, 1].copy(),
                                   radius * 0.98, half, 8)
    # normalised convolution: bins no pixel offset falls in (every lens at the same sub-pixel
    # phase, as on an ideal lattice of whole-pixel pitch) take their neighbours' mean
    weight = ndimage.gaussian_filter(counts, 1.0)
    mean = ndimage.gaussian_filter(sums, 1.0) / np.maximum(weight, 1e-9)
    # the peak among bins many pixels fall in: a bin at the disc's edge that one bright pixel
    # falls in would raise it and leave no bin usable
    filled = weight > 0.05 * weight.max()
    yy, xx = (np.indices(mean.shape) - 2 * half) / 2.0
    own = filled & (np.hypot(xx, yy) < _overlap_radius(mean, filled, np.hypot(xx, yy)))
    peak = float(np.max(mean[own])) if own.any() else 0.0
    if not peak > 0:
        raise ValueError("the micro-images hold no light (the frame is dark or NaN under the "
                         "grid); check the frames and the grid")
    usable = (mean >= USABLE_LEVEL * peak) & own
    usable &= np.hypot(xx, yy) <= radius * 0.95
    # the rim of a micro-image falls off within a pixel or two: its binned mean is not the
    # rim of each lens (sub-pixel centres), and the residual pattern, the same in every
    # micro-image, would pull every match towards zero shift
    usable = ndimage.binary_erosion(usable, iterations=RIM_BINS)
    mean = _smooth_profile(mean, counts, usable, xx / radius, yy / radius)
    profile = np.where(usable, mean, np.nan)
    r_use = float(np.max(np.hypot(xx, yy)[usable])) if usable.any() else 0.0
    if r_use < 2.0:
        raise ValueError(f"micro-images are usable over a radius of {r_use:.1f} px only; "
                         "depth needs micro-images of at least 4 px across")
    return profile, mean, half, r_use


def _overlap_radius(mean: np.ndarray, filled: np.ndarray, r: np.ndarray) -> float:
    """Offset (px) from which the mean micro-image grows brighter than it is nearer the
    centre by OVERLAP_RISE: there the micro-images overlap and neighbours' light adds (Boys2:
    0.57 of the peak at 14 px, 0.69 at 34 px, pitch 70 px), and a pixel shows two lenses'
    content at once. Vignetting alone only darkens outwards; inf when nothing rises."""
    rings = np.floor(r[filled]).astype(np.int64)
    sums = np.bincount(rings, weights=mean[filled])
    counts = np.bincount(rings)
    radial = sums[counts > 0] / counts[counts > 0]
    low = np.minimum.accumulate(radial)
    rise = np.flatnonzero(radial > (1 + OVERLAP_RISE) * low)
    return float(np.flatnonzero(counts > 0)[rise[0]]) if rise.size else np.inf


def _smooth_profile(mean, counts, usable, x, y) -> np.ndarray:
    """The profile over the usable disc as an even polynomial of degree PROFILE_DEGREE in the
    offset (least squares weighted by the samples per bin).

    The binned mean carries the scene averaged over only as many lenses as the frame has:
    offset u samples the scene s g u further along, so the scene's coarse gradients leave a
    tilt (odd in u) and its texture leaves noise, the same in every micro-image, which would
    bias every match. The mean vignetting of all lenses is point-symmetric (each lens is, and
    the field's off-axis shifts cancel across the frame) and smooth inside the rim: even
    terms keep it and drop both."""
    if usable.sum() < 4 * PROFILE_TERMS:
        return mean
    powers = [(a, b) for a in range(PROFILE_DEGREE + 1) for b in range(PROFILE_DEGREE + 1 - a)
              if (a + b) % 2 == 0]
    design = np.stack([x[usable] ** a * y[usable] ** b for a, b in powers], axis=1)
    weight = np.sqrt(counts[usable])
    coef, *_ = np.linalg.lstsq(design * weight[:, None], mean[usable] * weight, rcond=None)
    out = mean.copy()
    out[usable] = design @ coef
    return out


def lens_depth(frame: np.ndarray, grid: LensGrid, *, g_range: tuple[float, float] = (2.0, 8.0),
               type_ranges: np.ndarray | None = None) -> LensDepth:
    """g and confidence of every lens of ``grid`` on ``frame`` (2-D, NaN pixels unused).

    ``g_range`` (min, max) bounds the search; a Galilean (inverted) camera has negative g,
    e.g. (-8, -2). Both bounds share one sign and |g| > 1. A grid with lens types (a
    multi-focus array) matches each lens against its own type only, and the lens median takes
    the lenses of the type in focus where there are any: those sharper than their neighbours
    and, with ``type_ranges`` ((3, 2): min, max g of types 0, 1, 2, where each is in focus)
    that the frame bears out, whose g lies in their type's range.
    """
    gmin, gmax = check_range(g_range)
    img = np.ascontiguousarray(frame, np.float32)
    indices, centres = lens_table(grid, img.shape)
    if len(indices) < 7:
        raise ValueError(f"only {len(indices)} micro-images lie in the frame; depth needs "
                         "at least 7 (a lens and its neighbours)")
    cx, cy = centres[:, 0].copy(), centres[:, 1].copy()
    profile, gain, half, r_use = micro_profile(img, centres, grid.pitch_px)
    flat = np.full(img.shape, np.nan, np.float32)
    kn.normalise(img, cx, cy, profile, gain, half, flat)
    ring1, ring2 = RINGS[grid.lattice]
    coarse, fine, baseline = ring1[:len(ring1) // 2], ring1[::2] + ring2[::2], 1.0
    if grid.lens_type_of_coset is not None:
        # a multi-focus array: each lens against lenses of its own type (the second ring, one
        # coset), blurred alike at every depth, so the match is not pulled by a blur difference
        coarse, fine, baseline = ring2[:len(ring2) // 2], ring2, math.sqrt(3)
    q_lo, q_hi = sorted((1.0 / gmin, 1.0 / gmax))
    q_trusted = math.inf
    if grid.lens_type_of_coset is None:  # multi-focus arrays: see measurable_q
        q_lo, q_hi, q_trusted = measurable_q(q_lo, q_hi, grid.pitch_px, r_use, SHIFT_STEP_PX)
    n_q = max(3, int(math.ceil((q_hi - q_lo) * baseline * grid.pitch_px / SHIFT_STEP_PX)) + 1)
    qs = np.linspace(q_lo, q_hi, n_q)
    # q = 0 (no shift: the scene at infinity, or no scene) scored too: see _coarse
    ssd, cnt = kn.match_costs(flat, cx, cy, neighbours(indices, coarse),
                              profile, half, np.append(qs, 0.0), COARSE_STRIDE)
    min_samples = 0.1 * math.pi * r_use ** 2 / COARSE_STRIDE
    with np.errstate(invalid="ignore", divide="ignore"):
        cost = np.where(cnt >= min_samples, ssd / cnt, np.nan)
    q0, confidence = _coarse(cost[:, :-1], qs, unshifted=cost[:, -1])
    q = kn.refine_q(flat, cx, cy, neighbours(indices, fine), profile, half, q0,
                    q_lo, q_hi, REFINE_STEPS, REFINE_STRIDE)
    # an optimum pinned at a bound of the search is no minimum: the lens's g lies outside
    at_bound = (q <= q_lo + 1e-3 * (q_hi - q_lo)) | (q >= q_hi - 1e-3 * (q_hi - q_lo))
    at_bound |= np.abs(q) > q_trusted
    by_direction = direction_medians(
        flat, cx, cy, lambda offsets: neighbours(indices, offsets), coarse, profile, half,
        np.where(at_bound, np.nan, q), confidence, q_lo, q_hi, REFINE_STEPS, REFINE_STRIDE)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(np.isfinite(q) & ~at_bound, 1.0 / q, np.nan)
    prefer, used = None, None
    if grid.lens_type_of_coset is not None:
        prefer, used = _in_focus(flat, indices, centres, r_use, g, confidence,
                                 grid.lens_types(indices[:, 0], indices[:, 1]), type_ranges)
    if math.isfinite(q_trusted):
        g = drop_alone(g, neighbours(indices, ring1))
    g = lens_median(g, confidence, neighbours(indices, ring1), prefer=prefer)
    return LensDepth(centres, g, np.where(np.isfinite(g), confidence, 0.0), r_use, used,
                     by_direction)


def _in_focus(flat, indices, centres, r_use, g, confidence, types, type_ranges
              ) -> tuple[np.ndarray, bool | None]:
    """(K,) bool: the lenses of the type in focus where they are, and whether ``type_ranges``
    were used (None: none given).

    In focus: sharper than its six neighbours, which are of the two other types (mean
    |Laplacian| over the usable disc; the scene's detail cancels); with ranges, also g within
    its type's range. Ranges are used only when the frame bears them out (the lenses in range
    are sharper, by median, than those out of range): ranges of another camera, or swapped
    types, would prefer the blurred lenses."""
    from plenocli.calibration.lenstypes import local_contrast

    rows, relative = local_contrast(indices, _sharpness(flat, centres, r_use))
    sharper = np.zeros(len(g), bool)
    sharper[rows] = relative > 0
    if type_ranges is None:
        return sharper, None
    lo, hi = np.asarray(type_ranges, float)[types].T
    in_range = (g >= lo) & (g <= hi)
    judged = np.isfinite(g[rows]) & (confidence[rows] >= 0.1) & np.isfinite(relative)
    inside, outside = relative[judged & in_range[rows]], relative[judged & ~in_range[rows]]
    if min(inside.size, outside.size) < MIN_JUDGED or \
            not np.median(inside) > np.median(outside):
        return sharper, False
    return sharper & in_range, True


def _sharpness(flat: np.ndarray, centres: np.ndarray, r_use: float) -> np.ndarray:
    """Mean |Laplacian| of each flattened micro-image over its usable disc (K,): two disc
    filters over the frame (the sum and the count of usable pixels) read at the centres."""
    import cv2

    valid = cv2.erode(np.isfinite(flat).astype(np.uint8), np.ones((3, 3), np.uint8))
    # a pixel next to an unusable one has no Laplacian of its own micro-image
    lap = np.abs(cv2.Laplacian(np.nan_to_num(flat), cv2.CV_32F, ksize=3)) * valid
    half = int(r_use)
    dy, dx = np.mgrid[-half:half + 1, -half:half + 1]
    disc = (np.hypot(dx, dy) <= r_use).astype(np.float32)
    total = cv2.filter2D(lap, -1, disc, borderType=cv2.BORDER_CONSTANT)
    count = cv2.filter2D(valid.astype(np.float32), -1, disc, borderType=cv2.BORDER_CONSTANT)
    r = np.clip(np.rint(centres[:, 1]).astype(np.int64), 0, flat.shape[0] - 1)
    c = np.clip(np.rint(centres[:, 0]).astype(np.int64), 0, flat.shape[1] - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count[r, c] > 0.5, total[r, c] / count[r, c], np.nan)


def lens_median(g: np.ndarray, confidence: np.ndarray, nb: np.ndarray,
                min_confidence: float = 0.1, prefer: np.ndarray | None = None) -> np.ndarray:
    """Each lens's g replaced by the median over itself and its first ring (the confident
    ones): a lens sees a patch about one footprint across, its neighbours most of the same
    patch, so the median lowers the scatter of a surface without blurring a depth edge (the
    majority side wins, as it would at the lens's centre). With ``prefer`` (K,) bool, only the
    preferred ones of each neighbourhood count where it holds any: on a multi-focus array the
    lenses of the type in focus there; a blurred type's own-type match is biased towards
    small g by up to 0.65 (simulator, docs/depth.md)."""
    trusted = np.where(confidence >= min_confidence, g, np.nan)
    padded = np.append(trusted, np.nan)
    stack = np.concatenate([trusted[:, None], padded[np.where(nb >= 0, nb, -1)]], axis=1)
    if prefer is not None:
        chosen = np.append(prefer, False)
        chosen = np.concatenate([prefer[:, None], chosen[np.where(nb >= 0, nb, -1)]], axis=1)
        some = (chosen & np.isfinite(stack)).any(axis=1)
        stack = np.where(chosen | ~some[:, None], stack, np.nan)
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # lenses with no trusted value
            smoothed = np.nanmedian(stack, axis=1)
    return np.where(np.isfinite(g), np.where(np.isfinite(smoothed), smoothed, g), np.nan)


def _coarse(cost: np.ndarray, qs: np.ndarray,
            unshifted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best q of each lens's cost curve (parabola through the minimum and its neighbours) and
    the confidence 1 - best / reference, the reference being the median cost over the range or
    the ``unshifted`` cost (neighbours compared without a shift), whichever is lower. A
    micro-image whose neighbours match as well unshifted holds nothing that moves between them
    (a white, a blank wall: each micro-image is the lens's own vignetting and noise, the same in
    its neighbours): whatever minimum the range shows is not a depth, and its confidence is 0."""
    have = np.isfinite(cost).sum(axis=1) >= 3
    filled = np.where(np.isfinite(cost), cost, np.inf)
    k = np.argmin(filled, axis=1)
    rows = np.arange(len(cost))
    best = filled[rows, k]
    km, kp = np.clip(k - 1, 0, len(qs) - 1), np.clip(k + 1, 0, len(qs) - 1)
    cm, cp = filled[rows, km], filled[rows, kp]
    inner = (k > 0) & (k < len(qs) - 1) & np.isfinite(cm) & np.isfinite(cp)
    with np.errstate(invalid="ignore", divide="ignore"):
        curv = cm - 2 * best + cp
        frac = np.where(inner & (curv > 0), 0.5 * (cm - cp) / curv, 0.0)
        median = np.nanmedian(np.where(np.isfinite(cost), cost, np.nan)[have], axis=1)
    q0 = np.full(len(cost), np.nan)
    step = qs[1] - qs[0]
    q0[have] = qs[k[have]] + np.clip(frac[have], -0.5, 0.5) * step
    conf = np.zeros(len(cost))
    with np.errstate(invalid="ignore", divide="ignore"):
        reference = np.fmin(median, unshifted[have])
        conf[have] = np.clip(1.0 - best[have] / reference, 0.0, 1.0)
    conf[~np.isfinite(conf)] = 0.0
    return q0, conf


@dataclass(frozen=True)
class SignEvidence:
    """The micro-images match far better with g in ``other`` (min, max) than in the range
    searched: a camera of the other kind (``kind``); median lens confidences of both."""

    other: tuple[float, float]
    kind: str
    theirs: float
    ours: float

    def __str__(self) -> str:
        return (f"the micro-images match far better with g in {self.other[0]:g}:"
                f"{self.other[1]:g} (median confidence {self.theirs:.2f} against "
                f"{self.ours:.2f}): a {self.kind} camera")


def _other_sign(frame, grid, g_range, lenses: LensDepth, theirs: float | None = None
                ) -> SignEvidence | None:
    """Evidence that the frame matches far better with g of the other sign (a Galilean camera
    searched with a Keplerian range, or the reverse), or None. ``theirs``: the other sign's
    median confidence, when measured already."""
    ours = float(np.median(lenses.confidence))
    if ours >= CLEAR_MATCH:
        return None
    other = (-g_range[1], -g_range[0])
    if theirs is None:
        theirs = float(np.median(lens_depth(frame, grid, g_range=other).confidence))
    if theirs <= ours + SIGN_MARGIN:
        return None
    kind = "Galilean (inverted micro-images)" if other[0] < 0 else "Keplerian"
    return SignEvidence(other, kind, theirs, ours)


SIGN_CHECK_PX = 512    # side of the central region whose micro-images tell refocus g's sign


@dataclass(frozen=True)
class CentralMatch:
    """How the micro-images of a frame's central region match their neighbours on a grid:
    ``best``, the median lens confidence of the better sign of g searched, and ``evidence``
    when the other sign matches far better than the one asked for."""

    best: float
    evidence: SignEvidence | None


def central_match(frame: np.ndarray, grid: LensGrid, sign: float) -> CentralMatch | None:
    """:class:`CentralMatch` of ``frame``'s central region with g of ``sign`` (the other sign
    is searched only when this one matches weakly); None when the region holds too few lenses
    or the pitch measures no g. On a grid the frames cannot check, a weak ``best`` is what
    tells a wrong grid (another camera's, a few per cent off in pitch or turned):
    neighbours are compared at wrong offsets."""
    side = int(max(SIGN_CHECK_PX, 12 * grid.pitch_px))  # hundreds of lenses
    rows, cols = frame.shape
    top, left = max(0, (rows - side) // 2), max(0, (cols - side) // 2)
    crop, sub = frame[top:top + side, left:left + side], grid.shifted(left, top)
    limit = min(8.0, grid.pitch_px / MIN_SHIFT_PX)
    if limit <= 2.0:
        return None
    ours = (2.0, limit) if sign > 0 else (-limit, -2.0)
    try:
        lenses = lens_depth(crop, sub, g_range=ours)
    except ValueError:  # too few lenses in the region to judge
        return None
    median = float(np.median(lenses.confidence))
    if median >= CLEAR_MATCH:
        return CentralMatch(median, None)
    theirs = float(np.median(lens_depth(crop, sub, g_range=(-ours[1], -ours[0])).confidence))
    return CentralMatch(max(median, theirs), _other_sign(crop, sub, ours, lenses, theirs))


def check_range(g_range: tuple[float, float]) -> tuple[float, float]:
    """(min, max) of a valid search range or ValueError saying what is wrong."""
    gmin, gmax = (float(v) for v in g_range)
    if not (math.isfinite(gmin) and math.isfinite(gmax)):
        raise ValueError(f"g range must be MIN:MAX of finite numbers, got {gmin:g}:{gmax:g}")
    if not gmin < gmax:
        raise ValueError(f"g range must be MIN:MAX with MIN < MAX, got {gmin:g}:{gmax:g}")
    if gmin * gmax <= 0 or min(abs(gmin), abs(gmax)) <= 1.0:
        raise ValueError(f"g range {gmin:g}:{gmax:g}: both bounds need one sign and |g| > 1 "
                         "(a point at |g| <= 1 is seen by one micro-image only); Keplerian "
                         "cameras have g > 1, Galilean ones g < -1")
    return gmin, gmax


def check_measurable(g_range: tuple[float, float], pitch_px: float) -> None:
    """ValueError naming the range a grid of this pitch measures when a bound of ``g_range``
    lies past it: up to the |g| whose content shifts by MIN_SHIFT_PX between neighbouring
    micro-images (pitch / |g|); a search beyond finds shifts the match cannot tell from none
    (docs/depth.md)."""
    limit = float(pitch_px) / MIN_SHIFT_PX
    if max(abs(float(v)) for v in g_range) > limit:
        span = f"-{limit:.4g} <= g < -1" if float(g_range[0]) < 0 else f"1 < g <= {limit:.4g}"
        raise ValueError(f"g range {g_range[0]:g}:{g_range[1]:g} reaches past what this grid "
                         f"can measure: with micro-images {pitch_px:.4g} px apart, {span} (a "
                         f"shift of {MIN_SHIFT_PX:g} px or more between neighbours)")


def depth_map(frame: np.ndarray, grid: LensGrid, *, s: float = 0.2,
              g_range: tuple[float, float] = (2.0, 8.0), min_confidence: float = 0.1,
              type_ranges: np.ndarray | None = None) -> DepthMap:
    """g and confidence on the pixel grid of ``refocus(frame, grid, s=s)``; NaN where no lens
    with confidence >= ``min_confidence`` covers a pixel."""
    from plenocli.refocus import output_shape

    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"s must be a positive number (paper: 0.2), got {s}")
    if not 0 <= min_confidence <= 1:
        raise ValueError(f"min_confidence must be 0 to 1, got {min_confidence}")
    check_measurable(check_range(g_range), grid.pitch_px)
    lenses = lens_depth(frame, grid, g_range=g_range, type_ranges=type_ranges)
    evidence = _other_sign(frame, grid, g_range, lenses)
    if evidence is not None:   # every g found would be wrong
        raise ValueError(f"{evidence}; pass --g {evidence.other[0]:g}:{evidence.other[1]:g}")
    rows_out, cols_out = output_shape(np.shape(frame), s)
    weight = np.where(lenses.confidence >= max(min_confidence, 1e-6), lenses.confidence, 0.0)
    sg, sw, sc = kn.render_footprints(lenses.centres[:, 0].copy(), lenses.centres[:, 1].copy(),
                                      lenses.g, weight, RENDER_REACH * s * grid.pitch_px,
                                      float(s), rows_out, cols_out)
    with np.errstate(invalid="ignore", divide="ignore"):
        g = np.where(sw > 0, sg / sw, np.nan).astype(np.float32)
        conf = np.where(sw > 0, sc / sw, 0.0).astype(np.float32)
    return DepthMap(g, conf, lenses)


def lens_g_table(grid: LensGrid, shape: tuple[int, int], g_map: np.ndarray, s: float
                 ) -> tuple[np.ndarray, int, int]:
    """Each lens's g for all-in-focus rendering: the depth map (on the grid of
    ``refocus --s s``) where the lens's centre lands (s c_ij, which does not depend on g);
    lenses over unknown depth take the median of the known g.

    Returns (table, imin, jmin) for :func:`plenocli.refocus.refocus` ``lens_g``."""
    g_map = np.asarray(g_map, float)
    known = g_map[np.isfinite(g_map)]
    if not known.size:
        raise ValueError("the depth map holds no known g")
    indices, centres = lens_table(grid, shape)
    cols = np.clip(np.round(s * centres[:, 0]).astype(np.int64), 0, g_map.shape[1] - 1)
    rows = np.clip(np.round(s * centres[:, 1]).astype(np.int64), 0, g_map.shape[0] - 1)
    values = g_map[rows, cols]
    values = np.where(np.isfinite(values), values, float(np.median(known)))
    lo = indices.min(axis=0)
    table = np.full(indices.max(axis=0) - lo + 1, np.nan)
    table[indices[:, 0] - lo[0], indices[:, 1] - lo[1]] = values
    return table, int(lo[0]), int(lo[1])
