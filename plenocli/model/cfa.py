"""Bayer colour-filter-array bookkeeping: patterns, phases after crops, colour planes."""

from __future__ import annotations

import numpy as np

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")


def check_pattern(cfa: str) -> str:
    """``cfa`` upper-cased, if it is a 2 x 2 Bayer pattern (two greens on a diagonal, one red,
    one blue); else ValueError naming it. The one CFA check of plenocli.

    >>> check_pattern("rggb")
    'RGGB'
    """
    pattern = cfa.upper() if isinstance(cfa, str) else cfa
    if pattern not in BAYER_PATTERNS:
        raise ValueError(f"cfa {cfa!r} is not a 2 x 2 Bayer pattern "
                         f"(one of {', '.join(BAYER_PATTERNS)})")
    return pattern


def is_bayer(cfa: str | None) -> bool:
    """True for one of the four 2 x 2 Bayer patterns (any case)."""
    return isinstance(cfa, str) and cfa.upper() in BAYER_PATTERNS


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


def half_size_rgb(frame: np.ndarray, cfa: str) -> np.ndarray:
    """Half-size RGB of a Bayer frame: each 2 x 2 cell gives one pixel (greens averaged).

    Returns (rows // 2, cols // 2, 3) float32; a NaN in a cell makes that pixel's colour NaN.
    No interpolation: for registration and previews, where whole cells are what matters.
    """
    rows, cols = (frame.shape[0] // 2) * 2, (frame.shape[1] // 2) * 2
    out = np.zeros((rows // 2, cols // 2, 3), np.float32)
    for k, colour in enumerate(cfa.upper()):
        plane = frame[k // 2:rows:2, k % 2:cols:2]
        channel = "RGB".index(colour)
        out[..., channel] += plane * (0.5 if colour == "G" else 1.0)
    return out


def phase_gains(image: np.ndarray, *, max_blocks: int = 1 << 20) -> np.ndarray:
    """(2, 2) share of each pixel phase in the light of its 2 x 2 block: the median, over the
    brighter half of the blocks, of pixel / block mean. About 1 everywhere for a mono sensor
    (image detail averages out over many blocks); a Bayer mosaic without its pattern shows
    its channels' sensitivities (0.7-1.2 for a white). At most ``max_blocks`` blocks are read
    (whole block rows, evenly spaced)."""
    return phase_balance(image, max_blocks=max_blocks)[0]


def phase_balance(image: np.ndarray, *, max_blocks: int = 1 << 20
                  ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`phase_gains` and, per phase, the share (2, 2) of the brighter half of the blocks
    in which that phase is off its block's mean in the same direction as its median. A colour
    filter sets a phase's share in every block alike (a white's red phase is low in every
    block: 0.9-1.0); an imbalance that comes from the image's own detail at the 2-px scale, a
    micro-image's rim falling across a block, follows the image instead: its sign turns with
    the side of the lens (about 0.5-0.63 on mono whites of an even whole-pixel pitch)."""
    rows, cols = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
    if rows == 0 or cols == 0:
        return np.ones((2, 2)), np.full((2, 2), 0.5)
    step = max(1, -(-(rows // 2) * (cols // 2) // max_blocks))
    blocks = np.asarray(image[:rows, :cols], np.float32).reshape(rows // 2, 2, cols // 2, 2)
    blocks = blocks[::step]
    means = blocks.mean(axis=(1, 3))
    finite = np.isfinite(means)
    if not finite.any():
        return np.ones((2, 2)), np.full((2, 2), 0.5)
    bright = finite & (means >= np.median(means[finite])) & (means > 0)
    if not bright.any():
        return np.ones((2, 2)), np.full((2, 2), 0.5)
    shares = [[blocks[:, r, :, c][bright] / means[bright] for c in range(2)] for r in range(2)]
    gains = np.array([[np.median(share) for share in row] for row in shares])
    alike = np.array([[np.mean(np.sign(share - 1) == np.sign(gain - 1))
                       for share, gain in zip(row, grow, strict=True)]
                      for row, grow in zip(shares, gains, strict=True)])
    return gains, alike
