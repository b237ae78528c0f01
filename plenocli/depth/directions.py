"""Do a lenslet frame's micro-images agree on one depth whichever neighbour they are matched
against? (docs/depth.md, "Directions")

A scene point's virtual depth g is the point's, not the baseline's: matched only against the
neighbours along one lattice direction, the lenses give the same g, by median over the frame,
along every direction (simulated scenes within 1.7 %, real Raytrix captures within 4.0 %).
Behind a prism over part of the main lens, the parts of each micro-image look in different
directions: a neighbour along the line across the prism's edge shows another part of the scene
where a single g expects the same one, and that direction's median parts from the others by
7-10 % (raytrix-prism, three seeds), while the match over all neighbours together still looks
confident (96 % known, a third of it more than 0.5 off the true g = 4).
"""

from __future__ import annotations

import numpy as np

from plenocli.depth import kernels as kn

MAX_SPREAD = 0.05   # (max - min) / |median| of the direction medians: 4.0 % real, 7-10 % prism
MIN_LENSES = 50     # confident lenses below which the medians are not compared
CONFIDENT = 0.5
# the medians are taken over at most this many confident lenses, every k-th in the grid's
# (row by row) order, so spread over the frame; the same lenses along every direction, so the
# comparison is paired (the 8 Mpx bench frame's 14 000 lenses cost 0.35 s, 70 % of its depth)
SAMPLED_LENSES = 2000


def direction_medians(flat, cx, cy, neighbours_along, directions, profile, half, q,
                      confidence, q_lo, q_hi, steps, stride) -> np.ndarray | None:
    """Median g (one per lattice direction) of the lenses with a confident, finite ``q`` (at
    most about SAMPLED_LENSES of them), each refined against its two neighbours along that
    direction only (from ``q``); None when fewer than MIN_LENSES lenses are confident."""
    sure = np.isfinite(q) & (confidence >= CONFIDENT)
    if sure.sum() < MIN_LENSES:
        return None
    chosen = np.flatnonzero(sure)
    sure = np.zeros_like(sure)
    sure[chosen[::max(1, len(chosen) // SAMPLED_LENSES)]] = True
    start = np.where(sure, q, np.nan)
    found = []
    for di, dj in directions:
        nb = neighbours_along([(di, dj), (-di, -dj)])
        found.append(kn.refine_q(flat, cx, cy, nb, profile, half, start.copy(), q_lo, q_hi,
                                 steps, stride))
    q_dir = np.stack(found)[:, sure]
    # a direction's optimum pinned at a bound of the search is no measurement
    inside = (q_dir > q_lo + 1e-3 * (q_hi - q_lo)) & (q_dir < q_hi - 1e-3 * (q_hi - q_lo))
    keep = np.all(np.isfinite(q_dir) & (q_dir != 0) & inside, axis=0)
    if keep.sum() < MIN_LENSES:
        return None
    return np.median(1.0 / q_dir[:, keep], axis=1)


def check_directions(medians) -> None:
    """ValueError when the direction medians (or None: not compared) part by more than
    MAX_SPREAD."""
    if medians is None:
        return
    medians = np.asarray(medians, float)
    spread = float((medians.max() - medians.min()) / abs(np.median(medians)))
    if spread > MAX_SPREAD:
        shown = " / ".join(f"{g:.2f}" for g in medians)
        raise ValueError(
            f"the micro-images do not agree on one depth by direction: matched along each "
            f"lattice direction alone their lenses give g {shown} by median "
            f"({100 * spread:.0f} % apart; a scene gives <= {100 * MAX_SPREAD:g} %): they do "
            "not show one scene shifted by one g (parts looking in different directions behind "
            "a prism, or micro-images too small to match); nothing was written")
