"""How well the placed views line up, measured where it can be seen; a side file (a saved
transform, a rig) or a registration that does not line them up makes the panorama refused,
never wrong.

In every neighbour pair's overlap, up to eight blocks of at most ``BLOCK_PX`` square, tiling the
overlap from one end of the seam to the other, are warped at full resolution; in each block the
shift that best aligns the two warped views is found by normalised cross-correlation over whole-
pixel shifts within ``SEARCH_PX`` and a parabola through the peak, on the high-passed luminance
(exposure and vignetting do not move the peak). The RMS of the block shifts is the pair's
residual (the report's ``residual_px``); beyond ``TOLERANCE_PX`` the transform does not describe
these views. Short blocks along the whole seam (not one shift for the whole strip) also catch a
rig whose distortion model is wrong: its misfit changes along the seam and is largest at its
ends. A block of nearly no texture (under ``FLAT_FRACTION`` of the seam's most textured block)
that does not correlate is left out: it measures nothing. This works on overlaps down to ~20 px
wide and costs a few warps of small blocks whatever the view size."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from plenocli.io.transformfile import views_remedy
from plenocli.stitch import compose
from plenocli.stitch.errors import StitchError
from plenocli.stitch.views import erode, highpass

# A seam error under half a pixel is invisible after blending; a transform 1 px off shows.
TOLERANCE_PX = 0.5
APERTURE_FRACTION = 0.1  # a correlation peak this much flatter along one axis does not place it
SEARCH_PX = 4  # the search reaches 4 px (8 px at half resolution); beyond, the residual is "> 4"
MIN_CORRELATION = 0.3  # at the best shift: below it the overlap holds no common texture
# A block mostly outside what both views cover (a corner of the panorama where the views'
# edges curve) measures those edges, not the seam: it is left out.
MIN_COVERED = 0.5
BLOCK_PX = 192  # blocks of an overlap measured at full resolution: enough texture, little cost
ALONG_PX = 48  # a block's least length along the seam (with SEARCH_PX: >= 1000 pixels compared)
MAX_BLOCKS = 8
# A block whose texture is under this fraction of the seam's most textured block holds mostly
# noise (sky, a wall): with no correlation there it measures nothing, and a seam there is
# invisible, so it is left out rather than counted as misaligned.
FLAT_FRACTION = 0.1
# texture below this fraction of the block's level is no texture: a constant region resampled
# varies by float32 rounding (1e-7), a camera's darkest sky by its noise (1e-3 and more)
MIN_TEXTURE = 1e-5


def check_transform_names(transform: dict, names: list[str], layout: str, *,
                          named_after_files: bool, held: list[str] | None = None) -> None:
    """Refuse a saved transform whose view names are not these views' (unless the views are
    named after their files: another capture's files have other names) or whose layout a
    ``layout`` other than "auto" contradicts."""
    saved = transform.get("views")
    if saved is not None and not named_after_files and list(saved) != list(names):
        raise ValueError(f"the transform was made for views {','.join(map(str, saved))}, these "
                         f"are {','.join(names)}; {views_remedy(saved, held)}")
    if layout != "auto" and transform.get("layout") not in (None, layout):
        raise ValueError(f"--layout {layout} contradicts the transform's layout "
                         f"{transform.get('layout')}; drop --layout (the transform sets it)")


@dataclass(frozen=True)
class SeamFit:
    """How well a neighbour pair lines up on the panorama: the RMS (px) of the local shifts left
    along its seam (per axis, over the blocks that place it) and the blocks' lowest peak
    correlation."""

    residual_px: float
    correlation: float


def seam_fits(stack: np.ndarray, maps: list, boxes: list, pairs: list) -> list[SeamFit | None]:
    """Per neighbour pair (a, b, direction) of the views ``stack`` (V, C, rows, cols) placed by
    ``maps`` into ``boxes`` (:func:`plenocli.stitch.compose.place`): its :class:`SeamFit`, or
    None where no block holds enough of both views (a seam under about 20 x 20 px). The pairs
    are measured two at a time, in threads (OpenCV's warps and matches release the GIL)."""
    def fit(pair):
        a, b, _ = pair
        shifts, corrs = _seam_shifts(stack, maps, (a, b), compose.intersect(boxes[a], boxes[b]))
        if not shifts:
            return None
        # per axis over the blocks that constrain it (NaN: the block's texture runs along it)
        squares = np.square(np.array(shifts))
        residual = float(np.sqrt(sum(np.nanmean(c) for c in squares.T if np.isfinite(c).any())))
        return SeamFit(residual, min(corrs))

    with ThreadPoolExecutor(min(2, len(pairs))) as pool:
        return list(pool.map(fit, pairs))


# what to do when the views do not line up, by what placed them
_REGISTRATION_REMEDY = ("a false match, or views that no shift lines up: give the rig (--rig), "
                        "the expected overlap (--overlap) or the lens distortion "
                        "(--distortion), try --model homography, check the views' order "
                        "(--views)")
_SIDE_FILE_REMEDY = "register the views without it"
# a prism's views may not register without a rig: the remedy is the rig of this capture
_RIG_REMEDY = ("it is not this capture's rig (another prism, lens or focus): give the rig "
               "of the camera and prism that took it (its prism and lens values), or register "
               "the views without it")


def default_claim(*, transform: bool, rig: bool) -> tuple[str, str]:
    """(what placed the views, what to do if they do not line up), as a refusal says them."""
    if transform:
        return "the transform", _SIDE_FILE_REMEDY
    if rig:
        return "the rig", _RIG_REMEDY
    return "the registration", _REGISTRATION_REMEDY


def check_fits(fits: list, pairs: list, *, what: str, remedy: str) -> None:
    """Refuse (StitchError) views whose placement (``what`` names it in the message, ``remedy``
    says what to do) does not line them up within ``TOLERANCE_PX`` in every overlap, or leaves
    a pair no overlap large enough to check: ``fits`` from :func:`seam_fits`, one per pair."""
    for (a, b, _), fit in zip(pairs, fits, strict=True):
        if fit is None:
            raise StitchError(f"{what} leaves views {a} and {b} no overlap large enough, and "
                              f"textured, to check (about 20 x 20 px); it cannot be vouched "
                              f"for: {remedy}")
        if not fit.correlation >= MIN_CORRELATION or fit.residual_px > TOLERANCE_PX:
            shown = f"> {SEARCH_PX}" if fit.residual_px > SEARCH_PX else f"{fit.residual_px:.2f}"
            raise StitchError(f"{what} does not describe these views: views {a} and {b} are "
                              f"{shown} px apart in its overlap (correlation "
                              f"{fit.correlation:.2f}; at most {TOLERANCE_PX} px): {remedy}")


def _seam_shifts(stack: np.ndarray, maps: list, pair: tuple[int, int], region
                 ) -> tuple[list, list]:
    """The shifts aligning the pair's two warped views and their correlations, block by block
    along the seam (:func:`_blocks`); a textureless block that does not correlate is left out.
    When no block holds enough pixels (a seam about 20 px wide), fewer, longer blocks."""
    n = _block_count(region)
    while n >= 1:
        found_blocks = []
        for block in _blocks(region, n):
            crops = [compose.warp_region(stack[k], maps[k], block) for k in pair]
            both = (crops[0][1] > 0) & (crops[1][1] > 0)
            luma = [np.where(both, crop.mean(axis=0), np.nan) for crop, _ in crops]
            # a block's own edges are not no data: a block inside both views is all measured,
            # and OpenCV's unmasked template match (a third of the masked one's time) serves it
            ok = erode(np.isfinite(luma[0] + luma[1]), 2, outside=True)
            if ok.mean() < MIN_COVERED:
                continue
            # each view's texture against its own level, on that level: a view a million
            # times darker than its neighbour (another exposure, another unit) lines up the
            # same, and no unit is too small or too large for the float32 correlation
            levels = [float(np.nanmean(np.abs(v[ok]), dtype=np.float64)) for v in luma]
            if not min(levels) > 0:
                continue
            texture = [highpass(v / np.float32(level)) for v, level in zip(luma, levels,
                                                                             strict=True)]
            strength = min(float(np.std(t[ok], dtype=np.float64)) for t in texture)
            if not strength > MIN_TEXTURE:
                continue   # a constant (the arithmetic's rounding correlates, not the scene)
            found = _block_shift(*texture, ok)
            if found is not None:
                found_blocks.append((*found, strength))
        if found_blocks:
            strongest = max(t for _, _, t in found_blocks)
            kept = [(s, c) for s, c, t in found_blocks
                    if c >= MIN_CORRELATION or t >= FLAT_FRACTION * strongest]
            return [s for s, _ in kept], [c for _, c in kept]
        n //= 2
    return [], []


def _block_count(region) -> int:
    """One block per ALONG_PX of the seam's length, at most MAX_BLOCKS (0: no overlap)."""
    if region is None:
        return 0
    length = max(r.stop - r.start for r in region)
    return int(np.clip(length // ALONG_PX, 1, MAX_BLOCKS))


def _blocks(region, n: int) -> list:
    """``n`` blocks of at most BLOCK_PX x BLOCK_PX tiling an overlap ``region`` (canvas slices)
    from one end of the seam to the other, centred across it. A wrong distortion's misfit
    changes along the seam and grows towards its ends (away from the axis): longer blocks, or
    blocks that leave the ends out, average it away."""
    spans = [(r.start, r.stop) for r in region]
    long_axis = 0 if spans[0][1] - spans[0][0] >= spans[1][1] - spans[1][0] else 1
    lo, hi = spans[long_axis]
    size = min(BLOCK_PX, (hi - lo) // n)
    across_lo, across_hi = spans[1 - long_axis]
    mid = (across_lo + across_hi) // 2
    across = slice(max(across_lo, mid - BLOCK_PX // 2), min(across_hi, mid + BLOCK_PX // 2))
    out = []
    for start in np.linspace(lo, hi - size, n).round().astype(int):
        along = slice(int(start), int(start) + size)
        out.append((along, across) if long_axis == 0 else (across, along))
    return out


def _block_shift(a: np.ndarray, b: np.ndarray, ok: np.ndarray
                 ) -> tuple[np.ndarray, float] | None:
    """The sub-pixel shift (dy, dx) that best aligns ``b`` to ``a`` within SEARCH_PX and its
    correlation; None when the block holds too few pixels."""
    s = SEARCH_PX
    rows, cols = a.shape
    if rows < 2 * s + 12 or cols < 2 * s + 12:
        return None
    core = (slice(s, rows - s), slice(s, cols - s))
    valid = ok[core] & ok[:rows - 2 * s, :cols - 2 * s] & ok[2 * s:, 2 * s:]
    if valid.sum() < 256:
        return None
    scores = _scores(a, b, valid)
    iy, ix = np.unravel_index(int(np.argmax(scores)), scores.shape)
    shift = np.array([_vertex(scores[:, ix], iy), _vertex(scores[iy, :], ix)]) - s
    # the aperture problem: texture of one direction (edges along x, say) correlates alike at
    # every shift along it, so the peak's place along that axis is noise, not a misfit
    drops = np.array([_drop(scores[:, ix], iy), _drop(scores[iy, :], ix)])
    shift[drops < APERTURE_FRACTION * drops.max()] = np.nan
    return shift, float(scores[iy, ix])


def _scores(a: np.ndarray, b: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(2 s + 1, 2 s + 1) normalised cross-correlations of ``a``'s core (SEARCH_PX in from each
    side) with ``b`` shifted by (dy, dx), each mean-subtracted over the core's ``valid`` pixels
    (0 where either is flat there): OpenCV's template match, masked where not all is valid
    (float32 sums: within 1e-7 of float64 ones on the high-passed, zero-mean blocks it is
    given; an offset far above the texture would cost float32 its digits)."""
    s = SEARCH_PX
    rows, cols = a.shape
    template = a[s:rows - s, s:cols - s]
    if not np.ptp(template[valid]) > 0:
        return np.zeros((2 * s + 1, 2 * s + 1))  # OpenCV scores a flat template 1 or NaN
    mask = None if valid.all() else valid.astype(np.float32)
    found = cv2.matchTemplate(np.ascontiguousarray(b, np.float32),
                              np.ascontiguousarray(template, np.float32),
                              cv2.TM_CCOEFF_NORMED, mask=mask)
    # a flat window has no correlation; OpenCV leaves it undefined (NaN or inf)
    return np.where(np.isfinite(found), found, 0.0).astype(np.float64)


def _drop(values: np.ndarray, k: int) -> float:
    """How sharply the correlation peaks at ``values[k]``: its fall to both neighbours (the
    parabola's curvature; one side at the search's edge). A peak between two pixels falls
    little to the nearer one, so one side alone would not do."""
    sides = [values[k] - values[j] for j in (k - 1, k + 1) if 0 <= j < len(values)]
    return float(sum(sides) * 2 / len(sides))


def _vertex(values: np.ndarray, k: int) -> float:
    """Sub-pixel peak position by a parabola through ``values[k-1:k+2]`` (the edge: beyond)."""
    if k == 0 or k == len(values) - 1:
        return float(k) + (0.5 if k else -0.5)  # the peak lies beyond the search
    lo, mid, hi = values[k - 1], values[k], values[k + 1]
    den = lo - 2 * mid + hi
    return float(k) + (0.5 * (lo - hi) / den if den < 0 else 0.0)
