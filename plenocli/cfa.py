"""Bayer colour-filter-array bookkeeping: patterns, phases after crops, colour planes."""

from __future__ import annotations


def shift_pattern(cfa: str | None, row: int, col: int) -> str | None:
    """The 2 x 2 pattern seen from pixel (row, col) of a mosaic whose (0, 0) pattern is ``cfa``.

    >>> shift_pattern("RGGB", 1, 0)
    'GBRG'
    """
    if not cfa:
        return None
    return "".join(cfa[((row + k // 2) % 2) * 2 + (col + k % 2) % 2] for k in range(4))


def positions(cfa: str | None) -> list[tuple[int, int]]:
    """The (row, col) phases of a 2 x 2 pattern, or [(0, 0)] period-1 for no mosaic."""
    return [(k // 2, k % 2) for k in range(4)] if cfa else [(0, 0)]


def period(cfa: str | None) -> int:
    """2 for a Bayer mosaic, 1 for mono or already demosaiced data."""
    return 2 if cfa else 1
