"""Mixing calibration file: the mixing-matrix field M of a rig as a TIFF with provenance.

One float32 page per matrix entry and colour, each the (node_rows, node_cols) grid of M_kj at the
tile centres, named ``M[k<-j].colour`` (the share of pupil part j's light that view k records).
The metadata key ``mixing`` holds what ``plenocli unmix`` needs to apply it:

``views``       the V view names, in matrix order
``colours``     colour planes: ``["R", "G", "B"]`` or ``["L"]``
``layout``      ``"cfa"`` (views are Bayer mosaics, colour by pixel: ``cfa`` below),
                ``"channels"`` (views come as pages ``VIEW.R``, ``VIEW.G``, ``VIEW.B``) or
                ``"mono"``
``cfa``         the 2 x 2 pattern at pixel (0, 0) of the frame the field covers (layout cfa)
``frame_shape`` ``[rows, cols]`` of that frame (not "shape": tifffile reads a JSON
                description with a "shape" key as its own shaped-series metadata)
``node_rows``, ``node_cols``: pixel positions of the nodes
"""

from __future__ import annotations

import os

import numpy as np

from plenocli.errors import InputError
from plenocli.io import tiffio
from plenocli.model.mixing import MixingField

LAYOUTS = ("cfa", "channels", "mono")


def page_names(mixing: MixingField) -> list[str]:
    return [f"M[{k}<-{j}].{c}" for c in mixing.colours for k in mixing.views
            for j in mixing.views]


def write_mixing(path: str | os.PathLike, mixing: MixingField, *, layout: str,
                 cfa: str | None, meta: dict, protect: tuple = ()) -> None:
    """Write ``mixing`` with ``meta`` (provenance, history, report figures) atomically."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    n_c, n_v, _, n_r, n_k = mixing.nodes.shape
    pages = np.asarray(mixing.nodes, np.float32).reshape(n_c * n_v * n_v, n_r, n_k)
    info = {"views": list(mixing.views), "colours": list(mixing.colours), "layout": layout,
            "cfa": cfa, "frame_shape": [int(v) for v in mixing.shape],
            "node_rows": [float(v) for v in mixing.node_rows],
            "node_cols": [float(v) for v in mixing.node_cols]}
    tiffio.write_image(path, pages, {**meta, "views": page_names(mixing), "cfa": None,
                                     "mixing": info}, protect=protect)


def read_mixing(path: str | os.PathLike) -> tuple[MixingField, dict]:
    """The field and the file's full metadata (``meta["mixing"]`` as described above)."""
    pages, meta = tiffio.read_image(path)
    info = meta.get("mixing")
    if not isinstance(info, dict):
        raise InputError(f"{path}: not a mixing file (no 'mixing' in its metadata); make one "
                         "with plenocli crosstalk --mixing-out")
    try:
        views, colours = tuple(info["views"]), tuple(info["colours"])
        n_v, n_c = len(views), len(colours)
        nodes = np.asarray(pages, np.float64).reshape(n_c, n_v, n_v, *pages.shape[1:])
        field = MixingField(nodes, np.asarray(info["node_rows"], np.float64),
                            np.asarray(info["node_cols"], np.float64),
                            tuple(int(v) for v in info["frame_shape"]), views, colours)
        if info["layout"] not in LAYOUTS:
            raise ValueError(f"layout {info['layout']!r}")
    except (KeyError, ValueError, TypeError) as err:
        raise InputError(f"{path}: damaged mixing file ({err}); measure it again with "
                         "plenocli crosstalk --mixing-out") from err
    return field, meta
