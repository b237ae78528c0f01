"""Registration of a layout: the expected position of each neighbour pair (a rig's prediction or
an expected overlap), pairwise estimates, and their global solve into one transform per view."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from plenocli.progress import step
from plenocli.stitch.errors import StitchError
from plenocli.stitch.homography import (
    check_overlap,
    estimate_homography,
    features,
    overlap_fraction,
)
from plenocli.stitch.translation import estimate_translation
from plenocli.stitch.views import LAYOUTS, corners_xy, neighbour_pairs, translation_matrix

# A 2 x 2 layout reaches the fourth view two ways; correct pair registrations agree within a
# fraction of a pixel (noise), a wrong match by about the size of the shift it got wrong.
MAX_CLOSURE_PX = 2.0
# neighbour pairs registered at once: the two cores the stitch is sized for (SIFT, matching,
# warps and FFTs in OpenCV and numpy, and the refinement's numba kernels release the GIL)
PAIR_THREADS = 2


def difference_row(a: int, b: int, n_views: int) -> np.ndarray:
    """Design-matrix row of a pair measurement x_b - x_a, with view 0 fixed (x_0 = 0)."""
    row = np.zeros(n_views - 1)
    if b:
        row[b - 1] += 1
    if a:
        row[a - 1] -= 1
    return row


def _solve_translations(measured: list[tuple[int, int, np.ndarray]], n_views: int):
    """Least-squares positions p_k (p_0 = 0) from pair measurements p_b - p_a = d_ab."""
    m = np.array([difference_row(a, b, n_views) for a, b, _ in measured])
    r = np.array([d for _, _, d in measured])
    pos, *_ = np.linalg.lstsq(m, r, rcond=None)
    closure = float(np.sqrt(np.mean(np.sum((m @ pos - r) ** 2, axis=1))))
    return np.vstack([np.zeros(2), pos]), closure




def priors(layout: str, shape: tuple[int, int], origins: np.ndarray | None,
            overlap: float | None, overlap_tolerance: float, tolerance_px: float | None
            ) -> dict:
    """Expected shift (dy, dx) and search tolerance (px) per neighbour pair, or None."""
    rows, cols = shape
    out = {}
    for a, b, direction in neighbour_pairs(layout):
        if origins is not None:
            d = origins[b] - origins[a]
            out[(a, b)] = ((float(d[0]), float(d[1])), tolerance_px)
        elif overlap is not None:
            size = cols if direction == "h" else rows
            shift = (0.0, size * (1 - overlap)) if direction == "h" else (size * (1 - overlap),
                                                                           0.0)
            tol = tolerance_px if tolerance_px is not None else overlap_tolerance * size
            out[(a, b)] = (shift, tol)
        else:
            out[(a, b)] = (None, None)
    return out


def auto_layout(luma: np.ndarray, search: dict, overlap: float | None = None,
                overlap_tolerance: float = 0.1) -> str:
    """The layout of two views: side by side or one above the other, whichever overlap
    correlates best."""
    best, best_corr, errors = None, -np.inf, []
    for layout, direction in (("1x2", "h"), ("2x1", "v")):
        (prior, tol), = priors(layout, luma.shape[1:], None, overlap, overlap_tolerance,
                                None).values()
        try:
            _, _, info = estimate_translation(luma[0], luma[1], direction=direction, prior=prior,
                                              tolerance_px=tol, **search)
        except StitchError as err:
            errors.append(str(err))
            continue
        if info["correlation"] > best_corr:
            best, best_corr = layout, info["correlation"]
    if best is None:
        raise StitchError(f"no overlap found side by side nor one above the other ({errors[0]})")
    return best




class FeatureCache:
    """Each image's SIFT features (:func:`features`), found once though two pairs registered
    at once ask for them; keyed by (view, offset, shape) of the image."""

    def __init__(self):
        self._lock, self._locks, self._found = threading.Lock(), {}, {}

    def __call__(self, key: tuple, image: np.ndarray) -> tuple:
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            if key not in self._found:
                self._found[key] = features(image)
            return self._found[key]


def _measure_pair(images, a: int, b: int, direction: str, model: str, search: dict,
                  prior, tol, shape: tuple[int, int], found: FeatureCache | None = None
                  ) -> tuple[np.ndarray, dict]:
    """One neighbour pair: the shift [dy, dx] or the homography b -> a, and its report.
    ``images`` = (image of a, image of b, offset of a, offset of b): the views, or crops of them
    whose pixel (0, 0) is the views' pixel ``offset`` [dy, dx] (a rig's overlap strips);
    ``shape`` is the views' (rows, cols); ``found`` keeps each image's features for the next
    pair that uses the same image."""
    img_a, img_b, off_a, off_b = images
    to_crops = np.asarray(off_b, float) - np.asarray(off_a, float)
    local = None if prior is None else tuple(np.asarray(prior, float) + to_crops)
    try:
        if model == "translation":
            dy, dx, info = estimate_translation(img_a, img_b, direction=direction,
                                                prior=local, tolerance_px=tol, **search)
            dy, dx = dy - to_crops[0], dx - to_crops[1]
            size = shape[1] if direction == "h" else shape[0]
            along = dx if direction == "h" else dy
            info.update(overlap_px=float(size - along), overlap_fraction=float(1 - along / size))
            info["shift_px"] = [dy, dx]
            return np.array([dy, dx]), info
        found = FeatureCache() if found is None else found
        h, info = estimate_homography(
            img_a, img_b, direction=direction, min_correlation=search["min_correlation"],
            prior=local, tolerance_px=tol, max_overlap=None,
            found=(found((a, tuple(off_a), img_a.shape), img_a),
                   found((b, tuple(off_b), img_b.shape), img_b)))
        h = translation_matrix(*off_a) @ h @ translation_matrix(-off_b[0], -off_b[1])
        h /= h[2, 2]
        info["overlap_fraction"] = check_overlap(h, shape, direction, search["max_overlap"])
        info["homography"] = h.tolist()
        return h, info
    except StitchError as err:
        raise StitchError(f"views {a} and {b}: {err}") from err


def _chain_homographies(measured: dict, n_views: int, shape: tuple[int, int]):
    """View -> view 0 homographies from the pairs, and for 2 x 2 the closure (px): the largest
    corner disagreement of view 3 reached through view 1 and through view 2."""
    transforms = [np.eye(3)] * n_views
    transforms[1] = measured[(0, 1)]
    if n_views != 4:
        return transforms, None
    transforms[2] = measured[(0, 2)]
    via_1 = measured[(0, 1)] @ measured[(1, 3)]
    via_2 = measured[(0, 2)] @ measured[(2, 3)]
    transforms[3] = via_1 / via_1[2, 2]
    corners = corners_xy(shape)
    p1 = cv2.perspectiveTransform(corners, via_1)
    p2 = cv2.perspectiveTransform(corners, via_2 / via_2[2, 2])
    return transforms, float(np.max(np.linalg.norm((p1 - p2).reshape(-1, 2), axis=1)))


def _disjoint_first(pairs: list) -> list[int]:
    """The pairs' indices in the order they are started: each next one, when it can, shares no
    view with the ones started just before it (PAIR_THREADS - 1 of them)."""
    order, left = [], list(range(len(pairs)))
    while left:
        recent = {v for k in order[max(0, len(order) - PAIR_THREADS + 1):] for v in pairs[k][:2]}
        k = next((k for k in left if not recent & set(pairs[k][:2])), left[0])
        order.append(k)
        left.remove(k)
    return order


def register(pair_images, n_views: int, shape: tuple[int, int], layout: str, model: str,
             search: dict, expected: dict):
    """Transforms (view -> view 0), the per-pair reports and the closure (px, or None).
    ``pair_images(a, b, direction)`` gives the images a pair is registered on (see
    :func:`_measure_pair`); ``shape`` is the views' (rows, cols)."""
    pairs, found = neighbour_pairs(layout), FeatureCache()

    def measure(pair):
        a, b, direction = pair
        prior, tol = expected[(a, b)]
        step(f"registering views {a} and {b}")
        return _measure_pair(pair_images(a, b, direction), a, b, direction, model, search,
                             prior, tol, shape, found)

    # the pairs are independent; their results (and a refusal: the first pair's in order)
    # are those of one pair after the other. Pairs without a common view are started together,
    # so neither waits for the other's features of their view (2 x 2: (0, 1) with (2, 3))
    with ThreadPoolExecutor(min(PAIR_THREADS, len(pairs))) as pool:
        jobs = {k: pool.submit(measure, pairs[k]) for k in _disjoint_first(pairs)}
        results = [jobs[k].result() for k in range(len(pairs))]
    pair_info, measured = [], {}
    for (a, b, direction), (estimate, info) in zip(pairs, results, strict=True):
        prior, _ = expected[(a, b)]
        measured[(a, b)] = estimate
        if prior is not None:
            info["expected_shift_px"] = list(prior)
        pair_info.append({"views": [a, b], "direction": direction, **info})
    if model == "homography":
        transforms, closure = _chain_homographies(measured, n_views, shape)
    else:
        pos, closure = _solve_translations([(a, b, d) for (a, b), d in measured.items()],
                                           n_views)
        transforms, closure = [translation_matrix(*p) for p in pos], \
            (closure if n_views > 2 else None)
    if closure is not None and not closure <= MAX_CLOSURE_PX:
        guided = any(prior is not None for prior, _ in expected.values())
        advice = ("check that --rig or --overlap describes these views (the search looked "
                  "near the shifts they predict)") if guided else (
            "pass --rig or --overlap so the search looks near the expected shifts")
        raise StitchError(f"the pair registrations do not close around the 2 x 2 loop (closure "
                         f"{closure:.1f} px, at most {MAX_CLOSURE_PX:g}): one pair matched the "
                         f"wrong place; {advice}")
    return transforms, pair_info, closure


def check_transform(transform: dict, n_views: int, shape: tuple[int, int], model: str, *,
                    k1: float = 0.0, rig=None, frame_shape: tuple[int, int] | None = None,
                    max_overlap: float = 0.7):
    """The view transforms and layout of a saved transform, refused (StitchError, one line)
    unless it fits the views: its layout, view size, distortion and rig as given (``model``,
    its own: ``panorama._model_of``), finite
    matrices, view 0 the reference, and every neighbour pair overlapping along its direction
    by at most ``max_overlap`` (in ``frame_shape``: the rig's canvases, else the views)."""
    again = "register them again (without --transform-in)"
    try:
        mats = [np.asarray(t, dtype=np.float64) for t in transform["view_to_reference"]]
        layout = transform["layout"]
        view_shape = tuple(int(v) for v in transform["view_shape"])
        saved_k1 = float(transform.get("distortion_k1") or 0.0)
    except (KeyError, TypeError, ValueError, AttributeError) as err:
        raise StitchError(f"the transform is not a plenocli stitch transform (missing or bad "
                         f"{err}); save one with --transform-out") from err
    if layout not in LAYOUTS or LAYOUTS[layout][0] * LAYOUTS[layout][1] != len(mats):
        raise StitchError(f"the transform's layout {layout!r} does not fit its {len(mats)} view "
                         f"transforms; {again}")
    if len(mats) != n_views or any(m.shape != (3, 3) for m in mats):
        raise StitchError(f"the transform holds {len(mats)} view transforms for {n_views} views")
    if view_shape != tuple(shape):
        raise StitchError(f"the transform was made for views of {view_shape[-1]} x "
                         f"{view_shape[0]} px, these are {shape[1]} x {shape[0]}; {again}")
    if saved_k1 != k1:
        raise StitchError(f"the transform was made with --distortion {saved_k1:g}, not {k1:g}; "
                         f"pass --distortion {saved_k1:g} or {again}")
    saved_rig = transform.get("rig")
    if (saved_rig is None) != (rig is None) or (rig is not None and saved_rig != rig.to_dict()):
        made = "without a rig" if saved_rig is None else "with another rig than --rig gives"
        raise StitchError(f"the transform was made {made}; pass the rig it was made with or "
                         f"{again}")
    _check_matrices(mats, model, frame_shape or tuple(shape))
    for a, b, direction in neighbour_pairs(layout):
        h_ab = np.linalg.inv(mats[a]) @ mats[b]
        overlap = overlap_fraction(h_ab / h_ab[2, 2], frame_shape or tuple(shape), direction)
        if not 0 < overlap <= max_overlap:
            where = "right of" if direction == "h" else "below"
            raise StitchError(f"the transform does not fit these views: its layout {layout} "
                             f"puts view {b} {where} view {a}, but its matrices lay it "
                             f"{100 * overlap:.0f} % over view {a} "
                             f"along that direction (views that overlap: 0-"
                             f"{100 * max_overlap:.0f} %): it was made for another layout or "
                             f"capture; {again}")
    return mats, layout, "given"


def _check_matrices(mats: list[np.ndarray], model: str, shape: tuple[int, int]) -> None:
    """Finite matrices, view 0 the identity, translations pure shifts, and homographies that
    keep a view's corners within a view of where a shift would put them (no fold, no blow-up)."""
    if not all(np.isfinite(m).all() for m in mats) or not np.allclose(mats[0], np.eye(3),
                                                                      atol=1e-9):
        raise StitchError("the transform's matrices are not finite, or view 0's is not the "
                         "identity; save a transform with --transform-out")
    corners = corners_xy(shape)
    for k, m in enumerate(mats[1:], 1):
        shift_only = np.allclose(m[:2, :2], np.eye(2), atol=0) and np.allclose(m[2], [0, 0, 1],
                                                                             atol=0)
        if model == "translation" and not shift_only:
            raise StitchError(f"the transform's view {k} is not a translation though its model "
                             "says so; save a transform with --transform-out")
        moved = cv2.perspectiveTransform(corners, m / m[2, 2]).reshape(-1, 2)
        warp = moved - (corners.reshape(-1, 2) + [m[0, 2] / m[2, 2], m[1, 2] / m[2, 2]])
        if not np.isfinite(moved).all() or np.abs(warp).max() > 0.25 * max(shape) \
                or np.linalg.det(m[:2, :2] / m[2, 2]) <= 0:
            raise StitchError(f"the transform's view {k} folds or stretches the view (corners "
                             f"moved {np.abs(warp).max():.0f} px past a shift); it does not "
                             "describe a rig of overlapping views: register them again")
