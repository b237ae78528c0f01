"""Numba kernel of the dual/quad-pixel coarse search (``plenocli.depth.views._search``): one
pass per shift over the pixels keeps the running best, its neighbours and the two lowest
local minima. As numpy expressions the same bookkeeping made some thirty full-frame arrays per
shift, and the full-size search took 49 s on a 30 Mpx pair (the map had taken 6.5 s)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

# below this many pixels one thread: the search on the check's blocks of 128 x 128 px (some
# 900 calls) spent seconds waking the thread pool under load
SERIAL_BELOW = 1 << 18


def search_step(before, previous, cost, k, inner, shift, bound, best, left, right, k_best,
                total, low_cost, low_shift):
    """Take shift number ``k`` (its cost map ``cost``; ``previous`` and ``before`` the costs of
    shifts k - 1 and k - 2, or empty arrays before there are any) into the running state, in
    place: ``total``; ``right`` (the cost after the best so far); when ``inner`` (a shift
    the best may be), ``best``, ``left`` and ``k_best``; and where shift k - 1 (``shift`` px)
    is a local minimum whose parabola's vertex lies within +-``bound``, its vertex cost into
    ``low_cost`` / ``low_shift`` (2, rows, cols), the two lowest, lowest first."""
    step = _step_serial if cost.size < SERIAL_BELOW else _step_parallel
    step(before, previous, cost, k, inner, shift, bound, best, left, right, k_best, total,
         low_cost, low_shift)


@njit(cache=True, parallel=True)
def _step_parallel(before, previous, cost, k, inner, shift, bound, best, left, right, k_best,
                   total, low_cost, low_shift):
    for r in prange(cost.shape[0]):
        _row(r, before, previous, cost, k, inner, shift, bound, best, left, right, k_best,
             total, low_cost, low_shift)


@njit(cache=True)
def _step_serial(before, previous, cost, k, inner, shift, bound, best, left, right, k_best,
                 total, low_cost, low_shift):
    for r in range(cost.shape[0]):
        _row(r, before, previous, cost, k, inner, shift, bound, best, left, right, k_best,
             total, low_cost, low_shift)


@njit(cache=True)
def _row(r, before, previous, cost, k, inner, shift, bound, best, left, right, k_best, total,
         low_cost, low_shift):
    track = before.shape[0] > 0
    for c in range(cost.shape[1]):
        now = cost[r, c]
        total[r, c] += now
        if k_best[r, c] == k - 1:
            right[r, c] = now
        if track:
            b, p = before[r, c], previous[r, c]
            if p < b and p <= now:
                curv = b - 2.0 * p + now
                frac = 0.5 * (b - now) / curv if curv > 0 else 0.0
                if abs(shift + frac) <= bound:
                    value = max(p - 0.25 * (b - now) * frac, 0.0)
                    if value < low_cost[0, r, c]:
                        low_cost[1, r, c] = low_cost[0, r, c]
                        low_shift[1, r, c] = low_shift[0, r, c]
                        low_cost[0, r, c] = value
                        low_shift[0, r, c] = shift
                    elif value < low_cost[1, r, c]:
                        low_cost[1, r, c] = value
                        low_shift[1, r, c] = shift
        if inner and now < best[r, c]:
            left[r, c] = previous[r, c]
            right[r, c] = np.inf
            best[r, c] = now
            k_best[r, c] = k
