"""Disparity of quad-pixel views (2 x 2 SAIs S00, S01, S10, S11, docs/depth.md): the right
column against the left one and the bottom row against the top one, each measured as a
dual-pixel pair (``plenocli.depth.views``), the pages' directions checked pair by pair."""

from __future__ import annotations

import numpy as np

from plenocli.depth.views import Disparity, crossing, disparity_x, prepare

QUAD_AGREE_PX = 1.0     # x and y disparities of a quad-pixel pixel this far apart: unknown
QUAD_AGREE_SHARE = 0.1  # or this share of the disparity, whichever is larger
MIRRORED_SHARE = 0.5    # of the pixels measuring past QUAD_AGREE_PX / 2: opposite signs this
#                         often (and four times as often as one sign) is a mirrored set
NAMES = ("S00", "S01", "S10", "S11")
# (page, against page, along rows): S01 lies right of S00 and S11 right of S10 (their
# parallax runs along rows); S10 lies below S00 and S11 below S01 (along columns)
PAIRS = ((1, 0, True), (3, 2, True), (2, 0, False), (3, 1, False))


def quad_disparity(views: np.ndarray, *, max_disparity: float = 4.0
                   ) -> tuple[Disparity, Disparity]:
    """(x, y) disparities of 2 x 2 SAIs (S00, S01, S10, S11): right column against left,
    bottom row against top. ValueError when a pair's parallax runs the other way
    (``check_pairs``)."""
    s00, s01, s10, s11 = (np.asarray(v, np.float32) for v in views)
    check_pairs((s00, s01, s10, s11), int(np.ceil(max_disparity)))
    # each baseline is measured on its own and the two checked against each other (below)
    dx = disparity_x(0.5 * (s00 + s10), 0.5 * (s01 + s11), max_disparity=max_disparity,
                     check_rows=False)
    dy = disparity_x((0.5 * (s00 + s01)).T, (0.5 * (s10 + s11)).T, max_disparity=max_disparity,
                     check_rows=False)
    dy = Disparity(*(np.ascontiguousarray(v.T) for v in (dy.disparity, dy.confidence,
                                                         dy.repeat_px, dy.no_data)))
    # the two baselines of a 2 x 2 split are equal (the pupil's quarters sit at (+-c, +-c)),
    # so a defocused point has one disparity along both: where x and y disagree, one of them
    # matched texture at a wrong shift (simulated bands of 10-20 px: 59-99 % of a band known
    # and wrong, 5-24 % after; within 4 px x and y agree to 0.54 px, 99th percentile)
    check_mirrored(dx.disparity, dy.disparity)
    with np.errstate(invalid="ignore"):
        apart = ~(np.abs(dx.disparity - dy.disparity)
                  <= np.maximum(QUAD_AGREE_PX, QUAD_AGREE_SHARE
                                * np.abs(dx.disparity + dy.disparity) / 2))
    apart &= np.isfinite(dx.disparity) | np.isfinite(dy.disparity)
    for d in (dx, dy):
        d.disparity[apart] = np.nan
        d.confidence[apart] = 0.0
    return dx, dy


def check_mirrored(dx: np.ndarray, dy: np.ndarray) -> None:
    """ValueError when the x and y disparities agree in size but not in sign: a set mirrored
    left-right (S00 <-> S01 and S10 <-> S11 swapped) or up-down (S00 <-> S10, S01 <-> S11)
    negates one baseline's parallax only. Every pixel then disagrees and was dropped, and the
    views were refused as sharing no texture (audit 19 M1: a natural picture at 1.3 px, 0.05 %
    of the pixels clear). Only pixels measuring past QUAD_AGREE_PX / 2 tell a sign (nearer
    focus both readings fit); the picture in order at 0.6 and 1.3 px: 100 % agree in sign."""
    with np.errstate(invalid="ignore"):
        size = (np.abs(dx) + np.abs(dy)) / 2
        telling = size > QUAD_AGREE_PX / 2
        tolerance = np.maximum(QUAD_AGREE_PX, QUAD_AGREE_SHARE * size)
        same = telling & (np.abs(dx - dy) <= tolerance)
        opposite = telling & (np.abs(dx + dy) <= tolerance)
    count = int(telling.sum())
    if count < 0.01 * dx.size or opposite.sum() < max(MIRRORED_SHARE * count, 4 * same.sum()):
        return
    raise ValueError(f"the quad-pixel views' x and y disparities agree in size but not in "
                     f"sign ({100 * opposite.sum() / count:.0f} % of the pixels measuring past "
                     f"{QUAD_AGREE_PX / 2:g} px, the same sign {100 * same.sum() / count:.0f} "
                     "%): a mirrored set, S00 and S01 (and S10 and S11) swapped (left-right) "
                     "or S00 and S10 (and S01 and S11) swapped (up-down); give the pages as "
                     "S00 (top left), S01 (right of it), S10 (below it), S11; nothing was "
                     "written")


def check_pairs(views, reach: int) -> None:
    """ValueError naming the pages whose parallax runs the other way: S01 against S00 (and S11
    against S10) must differ along rows, S10 against S00 (and S11 against S01) along columns.
    The columns' and rows' averages are matched along one axis each, and pages in the other
    order (S01 and S10 swapped) or views turned by 90 degrees (a portrait capture, a
    transposed set) leave each average's parallax across its search: natural pictures read
    wrong on 40-70 % of their known pixels, exit 0 (audit 18 W4). The dual-pixel check
    (``views.crossing``), pair by pair: in order 0-0.1 % of the clear matches (0-1.9 % of
    those on texture of two directions), swapped or transposed 25-58 % (84-100 %)."""
    prepared = [prepare(v)[0] for v in views]
    wrong = []
    for page, against, rows in PAIRS:
        a, b = prepared[against], prepared[page]
        if not rows:
            a, b = np.ascontiguousarray(a.T), np.ascontiguousarray(b.T)
        found = crossing(a, b, reach)
        if found:
            wrong.append((page, against, rows, found))
    if not wrong:
        return
    page, against, rows, (share, where) = wrong[0]
    if len(wrong) == len(PAIRS):
        names = "every pair (S01 lies above or below S00, S10 beside it)"
        cause = ("S01 and S10 are swapped (pages in the other order) or the views are turned "
                 "by 90 degrees or transposed (a portrait capture)")
    else:
        names = ", ".join(f"{NAMES[p]} against {NAMES[q]}" for p, q, _, _ in wrong)
        cause = "the pages are not in the order S00 S01 S10 S11"
    raise ValueError(f"the quad-pixel views' parallax runs the other way for {names}: "
                     f"{NAMES[page]} against {NAMES[against]}, a "
                     f"{'vertical' if rows else 'horizontal'} shift explains "
                     f"{100 * share:.0f} % of their {where}, which no "
                     f"{'horizontal' if rows else 'vertical'} one does (pages in order: "
                     f"under 3 %); {cause}: give the pages as S00 (top left), S01 (right of "
                     "it), S10 (below it), S11, the views turned so that S01's content lies "
                     "beside S00's along rows; nothing was written")
