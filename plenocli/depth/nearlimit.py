"""Where a lenslet depth search stops at the near end: the |g| below which neighbouring
micro-images share too little of their usable disc for a match (docs/depth.md)."""

from __future__ import annotations

import math

import numpy as np

MIN_SHARED = 0.05     # share of the usable disc neighbours must have in common at the nearest g


def _overlap_share(shift: float, radius: float) -> float:
    """Share of a disc of ``radius`` that the same disc moved by ``shift`` covers."""
    h = min(1.0, shift / (2 * radius))
    return (2 * math.acos(h) - 2 * h * math.sqrt(1 - h * h)) / math.pi


def measurable_q(q_lo: float, q_hi: float, pitch_px: float, r_use: float, step_px: float
                 ) -> tuple[float, float, float]:
    """The search's (q_lo, q_hi) cut at the largest |q| (nearest |g|) whose shift between
    neighbours ``pitch_px`` apart still leaves two usable discs MIN_SHARED in common, and the
    largest |q| trusted: one candidate step (``step_px`` of shift) inside the cut or inside the
    range's own near bound (a plane at g 1.9 searched from 2 read 2.06, 59 % known).
    Past the cut neighbours share too little content and the best match lands near where
    they last do (usable disc 11.7 px, pitch 20.2: a plane at g 1.3 read 1.57, 1.5 read
    1.66, 1.7 read 1.78, 98 % known), so a lens found there is unknown (now 5-10 % known;
    from g 2.3 on 98 % as before). ValueError when the whole range lies past the cut.

    Not applied to a multi-focus array, matched across the second ring (sqrt(3) pitches):
    its cut would lie at g 3.4 on the simulator, whose slanted plane reads within 0.07-0.16
    RMS down to g 2.5 and would lose that part to a fifth of its lenses, wrong by 1.5."""
    lo, hi = 0.0, 2 * r_use
    for _ in range(40):  # the share falls monotonically with the shift
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _overlap_share(mid, r_use) >= MIN_SHARED else (lo, mid)
    q_max = lo / pitch_px
    trusted = q_max - step_px / pitch_px
    if min(abs(q_lo), abs(q_hi)) >= trusted:
        g_lo, g_hi = sorted((1 / q_lo, 1 / q_hi))
        raise ValueError(f"g range {g_lo:g}:{g_hi:g} lies nearer than these micro-images "
                         f"measure: usable over {2 * r_use:.1f} px of a {pitch_px:.4g} px "
                         f"pitch, neighbours share content for |g| > {1 / trusted:.3g} only; "
                         "search farther")
    near = max(abs(q_lo), abs(q_hi))
    if near <= q_max:   # the range's own near bound: its margin alike
        return q_lo, q_hi, near - step_px / pitch_px
    return max(q_lo, -q_max), min(q_hi, q_max), trusted


def drop_alone(g: np.ndarray, nb: np.ndarray) -> np.ndarray:
    """g without the lenses most of whose first ring found none. The lenses whose depth lies
    past the near end of the search (measurable_q) still find a minimum here and there by
    chance (5-16 % of a plane at g 1.1-2.15, wrong by 0.1-1.8); where micro-images share
    content, their neighbours find it too."""
    ring = np.append(g, np.nan)[np.where(nb >= 0, nb, -1)]
    alone = np.isfinite(ring).sum(axis=1) < 0.5 * (nb >= 0).sum(axis=1)
    return np.where(alone, np.nan, g)
