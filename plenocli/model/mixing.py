"""The mixing-matrix field of a prism rig: view k records sum_j M_kj T_j, M smooth over the
frame, given on a grid of nodes (tile centres) and bilinear between them (linear beyond the
outer nodes). Measured by ``plenocli.crosstalk.measure_mixing``, stored by
``plenocli.io.mixingfile``, solved by ``plenocli.unmix``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

MAX_REGULARISE = 1.0  # lambda above M's diagonal damps the views more than it unmixes them


@dataclass(frozen=True)
class MixingField:
    """A smooth mixing-matrix field: ``nodes[c, k, j, a, b]`` is M_kj of colour c at node
    (``node_rows[a]``, ``node_cols[b]``) in pixels of a (rows, cols) = ``shape`` frame."""

    nodes: np.ndarray
    node_rows: np.ndarray
    node_cols: np.ndarray
    shape: tuple[int, int]
    views: tuple[str, ...]
    colours: tuple[str, ...]

    def __post_init__(self):
        nodes = np.asarray(self.nodes)
        if nodes.ndim != 5 or nodes.shape[1] != nodes.shape[2]:
            raise ValueError(f"nodes must be (colours, V, V, node_rows, node_cols), got "
                             f"shape {nodes.shape}")
        n_c, n_v, _, n_r, n_k = nodes.shape
        if n_v < 2 or len(self.views) != n_v or len(self.colours) != n_c:
            raise ValueError(f"nodes {nodes.shape} do not fit {len(self.views)} views and "
                             f"{len(self.colours)} colours")
        for name, axis, n in (("node_rows", self.node_rows, n_r), ("node_cols", self.node_cols,
                                                                    n_k)):
            axis = np.asarray(axis)
            if axis.shape != (n,) or (n > 1 and np.any(np.diff(axis) <= 0)):
                raise ValueError(f"{name} must be {n} increasing positions, got {axis}")

    @property
    def n_views(self) -> int:
        return self.nodes.shape[1]

    def at_pixels(self) -> np.ndarray:
        """The per-pixel field (colours, V, V, rows, cols) float64 (for tests and simulation)."""
        r0, r1, wr = axis_weights(np.asarray(self.node_rows, np.float64), self.shape[0])
        c0, c1, wc = axis_weights(np.asarray(self.node_cols, np.float64), self.shape[1])
        n = np.asarray(self.nodes, np.float64)
        rows = n[..., r0, :] * (1 - wr)[:, None] + n[..., r1, :] * wr[:, None]
        return rows[..., c0] * (1 - wc) + rows[..., c1] * wc


def tile_centres(size: int, tile_px: int) -> np.ndarray:
    """Centres (px) of the tiles of side ``tile_px`` along an axis of ``size`` pixels, the last
    tile partial: where ``crosstalk.measure_mixing`` puts its nodes."""
    starts = np.arange(0, size, tile_px, dtype=np.float64)
    return (starts + np.minimum(starts + tile_px, size) - 1) / 2.0


def axis_weights(nodes: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear indices (lo, hi) and weights of pixels 0..n-1 on node positions ``nodes``."""
    pos = np.arange(n, dtype=np.float64)
    if len(nodes) == 1:
        zero = np.zeros(n, np.int64)
        return zero, zero, np.zeros(n)
    lo = np.clip(np.searchsorted(nodes, pos, side="right") - 1, 0, len(nodes) - 2)
    # Linear beyond the outer nodes (half a tile at most): exact for a linear field, where
    # holding the edge value would bias the frame border.
    w = (pos - nodes[lo]) / (nodes[lo + 1] - nodes[lo])
    return lo.astype(np.int64), (lo + 1).astype(np.int64), w
