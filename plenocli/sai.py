"""Sub-aperture images (SAIs) of plenoptic sensors (paper Eq. 1).

Ideal N x N plenoptic sensor: every micro-image is exactly N x N pixels, aligned with the pixel
grid, so the SAIs are a plain demultiplexing of the sensor image L (rows, cols)::

    S_ij(k, l) = L(k * N + i, l * N + j),   i, j in [0, N[

View ``i * N + j`` is named ``S{i}{j}``: i is the row inside the micro-image (0 = top), j the
column (0 = left). For a quad-pixel sensor (N = 2): S00 top-left, S01 top-right, S10
bottom-left, S11 bottom-right.

Colour. Two layouts of a Bayer colour-filter array are handled without demosaicing:

``micro-image`` (quad-Bayer): one colour filter covers a whole N x N micro-image, and the
    micro-images follow the 2 x 2 pattern ``cfa`` (period 2N pixels). Every SAI is then itself a
    Bayer mosaic with the same pattern ``cfa``.
``pixel``: an ordinary per-pixel Bayer pattern under the micro-lenses. For even N every SAI sees
    one colour only (S_ij has the colour of pattern position (i mod 2, j mod 2)); for odd N every
    SAI is a Bayer mosaic whose pattern is ``cfa`` shifted by (i, j).

When the pitch is not an integer number of pixels, the paper still extracts approximate SAIs
S-hat by taking, for each micro-image, the pixel nearest to the sub-aperture's position (nearest
neighbour instead of interpolation, so angular samples are never mixed):
:func:`approximate_sai`.
"""

from __future__ import annotations

import numpy as np

from plenocli.model.cfa import shift_pattern
from plenocli.model.lensgrid import LensGrid

CFA_LAYOUTS = ("pixel", "micro-image")
MIN_LENSES = 4  # micro-images per side: fewer make views too small to be images


def view_names(n: int) -> list[str]:
    """Names of the N x N views in order i * N + j: S00, S01, ...; from N = 10 on, i and j
    take two digits each (S0011 is i 0, j 11: S011 could be either)."""
    width = len(str(n - 1))
    return [f"S{i:0{width}d}{j:0{width}d}" for i in range(n) for j in range(n)]


def _check_n(n) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be a positive integer (pixels per micro-image side), got {n!r}")
    return int(n)


def demultiplex(frame: np.ndarray, n: int) -> np.ndarray:
    """Eq. 1: the N x N sub-aperture images of an ideal plenoptic sensor image.

    Parameters
    ----------
    frame : ndarray, (rows, cols)
        Sensor image; micro-image (k, l) covers rows k*N .. k*N+N-1, columns l*N .. l*N+N-1.
        Its size must be a whole number of micro-images, at least MIN_LENSES of them per side
        (a frame that is not is refused, with the crop that would fit).
    n : int
        Pixels per micro-image side.

    Returns
    -------
    ndarray, (n * n, rows // n, cols // n), same dtype
        View i * n + j is S_ij(k, l) = frame[k * n + i, l * n + j].
    """
    n = _check_n(n)
    frame = np.asarray(frame)
    if frame.ndim != 2:
        raise ValueError(f"frame must be 2-D (rows, cols), got shape {frame.shape}")
    rows, cols = frame.shape[0] // n, frame.shape[1] // n
    if min(rows, cols) < MIN_LENSES:
        raise ValueError(f"a {frame.shape[1]} x {frame.shape[0]} frame holds "
                         f"{cols} x {rows} micro-images of {n} x {n} pixels; the views need "
                         f"at least {MIN_LENSES} x {MIN_LENSES} (check n)")
    if (rows * n, cols * n) != frame.shape:
        raise ValueError(f"a {frame.shape[1]} x {frame.shape[0]} frame is not a whole number of "
                         f"{n} x {n} micro-images: check n, or give frames of "
                         f"{rows * n} rows and {cols * n} columns that start with a whole "
                         "micro-image")
    blocks = frame.reshape(rows, n, cols, n)
    return np.ascontiguousarray(blocks.transpose(1, 3, 0, 2).reshape(n * n, rows, cols))


def sai_colours(cfa: str | None, n: int, *, layout: str = "pixel") -> list[str | None]:
    """Colour description of each SAI (order i * N + j).

    Returns, per view, a 2 x 2 Bayer pattern (the SAI is a mosaic), a single letter "R", "G",
    "B" (the SAI holds one colour), or None (no CFA). See the module docstring.
    """
    n = _check_n(n)
    if layout not in CFA_LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(CFA_LAYOUTS)}, got {layout!r}")
    if not cfa:
        return [None] * (n * n)
    cfa = cfa.upper()
    if layout == "micro-image":
        return [cfa] * (n * n)
    if n % 2 == 0:
        return [cfa[(i % 2) * 2 + j % 2] for i in range(n) for j in range(n)]
    return [shift_pattern(cfa, i, j) for i in range(n) for j in range(n)]


def approximate_sai(frame: np.ndarray, grid: LensGrid, n: int) -> tuple[np.ndarray, np.ndarray]:
    """S-hat: approximate N x N SAIs of a square-lattice sensor whose pitch is not N pixels.

    Sub-aperture (i, j) of lens (a, b) is the pixel nearest to
    c_ab + ((j - (N-1)/2) * P/N, (i - (N-1)/2) * P/N) (x, y; P the pitch), i.e. the centre of
    the (i, j) cell of an N x N partition of the micro-image. Lenses are arranged by lattice
    index: the lattice vector closer to +x runs along columns. Centres are the grid's refined
    centres when it has them.

    Returns
    -------
    views : ndarray, float32, (n * n, lens rows, lens cols)
        NaN where a lens is missing or its sample falls outside the frame.
    centres : ndarray, float64, (lens rows, lens cols, 2)
        The (x, y) centre used for each output pixel (NaN when missing).
    """
    n = _check_n(n)
    frame = np.asarray(frame)
    if frame.ndim != 2:
        raise ValueError(f"frame must be 2-D (rows, cols), got shape {frame.shape}")
    if grid.lattice != "square":
        raise ValueError("approximate SAIs need a square lens lattice (ideal plenoptic sensor); "
                         f"this grid is {grid.lattice}: use refocus views for hex grids")
    if grid.pitch_px < n:
        raise ValueError(f"a micro-image of {grid.pitch_px:g} px cannot hold {n} x {n} "
                         "sub-apertures of at least one pixel; use a smaller n")
    shaped = grid if grid.image_shape or grid.centres_xy is not None else None
    if shaped is None:
        from dataclasses import replace

        shaped = replace(grid, image_shape=frame.shape)
    indices, centres = shaped.lens_centres()
    if len(indices) < MIN_LENSES * MIN_LENSES:
        raise ValueError(f"the grid has {len(indices)} lenses on a {frame.shape[1]} x "
                         f"{frame.shape[0]} frame; the views need at least "
                         f"{MIN_LENSES} x {MIN_LENSES}")
    basis = grid.basis()
    # column index: the lattice vector more aligned with +x; flip so indices grow along +x / +y
    col_axis = int(np.argmax(np.abs(basis[:, 0])))
    row_axis = 1 - col_axis
    col_sign = 1 if basis[col_axis, 0] > 0 else -1
    row_sign = 1 if basis[row_axis, 1] > 0 else -1
    k_col = col_sign * indices[:, col_axis]
    k_row = row_sign * indices[:, row_axis]
    k_col, k_row = k_col - k_col.min(), k_row - k_row.min()
    shape = (int(k_row.max()) + 1, int(k_col.max()) + 1)
    table = np.full(shape + (2,), np.nan)
    table[k_row, k_col] = centres
    step = grid.pitch_px / n
    views = np.full((n * n,) + shape, np.nan, np.float32)
    rows, cols = frame.shape
    for i in range(n):
        for j in range(n):
            x = np.rint(table[..., 0] + (j - (n - 1) / 2) * step)
            y = np.rint(table[..., 1] + (i - (n - 1) / 2) * step)
            ok = np.isfinite(x) & np.isfinite(y)
            ok[ok] = (x[ok] >= 0) & (x[ok] < cols) & (y[ok] >= 0) & (y[ok] < rows)
            views[i * n + j][ok] = frame[y[ok].astype(np.int64), x[ok].astype(np.int64)]
    return views, table
