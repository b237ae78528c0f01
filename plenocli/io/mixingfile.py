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

from plenocli.errors import InputError, library_words
from plenocli.io import tiffio
from plenocli.model.cfa import is_bayer
from plenocli.model.mixing import MixingField, tile_centres

LAYOUTS = ("cfa", "channels", "mono")
# measure_mixing writes M_jj = flux / flux = 1 exactly (float32); shares of light are >= 0 up to
# the noise of a tile's flux ratio, far below this
DIAGONAL_TOLERANCE = 1e-4
NEGATIVE_SHARE = 0.05
NODE_TOLERANCE_PX = 1e-3  # node positions are written as exact halves of a pixel


def page_names(mixing: MixingField) -> list[str]:
    return [f"M[{k}<-{j}].{c}" for c in mixing.colours for k in mixing.views
            for j in mixing.views]


def write_mixing(path: str | os.PathLike, mixing: MixingField, *, layout: str,
                 cfa: str | None, meta: dict, made_by: list[str] | None = None,
                 protect: tuple = ()) -> None:
    """Write ``mixing`` with ``meta`` (provenance, history, report figures) atomically;
    ``made_by``: the stages that made the views it was measured on (sealed with it)."""
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, got {layout!r}")
    n_c, n_v, _, n_r, n_k = mixing.nodes.shape
    pages = np.asarray(mixing.nodes, np.float32).reshape(n_c * n_v * n_v, n_r, n_k)
    info = {"views": list(mixing.views), "colours": list(mixing.colours), "layout": layout,
            "cfa": cfa, "frame_shape": [int(v) for v in mixing.shape],
            "node_rows": [float(v) for v in mixing.node_rows],
            "node_cols": [float(v) for v in mixing.node_cols], "views_made_by": made_by}
    tiffio.write_image(path, pages, {**meta, "views": page_names(mixing), "cfa": None,
                                     "mixing": info}, protect=protect, seal=True)


def read_mixing(path: str | os.PathLike) -> tuple[MixingField, dict]:
    """The field and the file's full metadata (``meta["mixing"]`` as described above), checked
    against what it claims (see :func:`check_mixing`)."""
    pages, meta = tiffio.read_image(path)
    info = meta.get("mixing")
    if not isinstance(info, dict):
        raise InputError(f"{path}: not a mixing file (no 'mixing' in its metadata); make one "
                         "with plenocli crosstalk --mixing-out")
    try:
        _check_names(info)
        views, colours = tuple(info["views"]), tuple(info["colours"])
        n_v, n_c = len(views), len(colours)
        nodes = np.asarray(pages, np.float64).reshape(n_c, n_v, n_v, *pages.shape[1:])
        field = MixingField(nodes, np.asarray(info["node_rows"], np.float64),
                            np.asarray(info["node_cols"], np.float64),
                            _frame_shape(info["frame_shape"]), views, colours)
        if info["layout"] not in LAYOUTS:
            raise ValueError(f"layout {info['layout']!r}")
    except (KeyError, ValueError, TypeError) as err:
        raise InputError(f"{path}: damaged mixing file ({library_words(err)}); measure it "
                         "again with plenocli crosstalk --mixing-out") from err
    if meta.get("views") != page_names(field):
        raise InputError(f"{path}: its pages are not named for views {','.join(views)} and "
                         f"colours {','.join(colours)} (M[k<-j].colour); the file was edited or "
                         "damaged: measure it again with plenocli crosstalk --mixing-out")
    check_mixing(path, field, info)
    tiffio.check_seal(path, pages, meta, "measure it again with plenocli crosstalk --mixing-out")
    return field, meta


def _check_names(info: dict) -> None:
    """Views: distinct non-empty names; colours: R, G, B (cfa / channels) or L (mono)."""
    views, colours = info["views"], info["colours"]
    if not (isinstance(views, list) and len(views) >= 2
            and all(isinstance(v, str) and v.strip() for v in views)
            and len(set(views)) == len(views)):
        raise ValueError(f"views {views!r} are not two or more distinct names")
    expected = {"cfa": ["R", "G", "B"], "mono": ["L"]}.get(info.get("layout"))
    if not isinstance(colours, list) or (colours != expected if expected else not (
            colours and set(colours) <= {"R", "G", "B"} and len(set(colours)) == len(colours))):
        raise ValueError(f"colours {colours!r} do not fit layout {info.get('layout')!r}")
    cfa = info.get("cfa")
    if (info.get("layout") == "cfa") != (cfa is not None) or not (
            cfa is None or (isinstance(cfa, str) and is_bayer(cfa))):
        raise ValueError(f"cfa {cfa!r} does not fit layout {info.get('layout')!r} (a Bayer "
                         "pattern for cfa, null otherwise)")


def _frame_shape(values) -> tuple[int, int]:
    if not (isinstance(values, list) and len(values) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in values)):
        raise ValueError(f"frame_shape {values!r} is not two positive whole numbers")
    return values[0], values[1]


def check_mixing(path, field: MixingField, info: dict) -> None:
    """What a measured field is (crosstalk.measure_mixing): finite, M_jj = 1 exactly (each
    masked white's flux divided by its intended view's), no negative share of light beyond
    noise, no share of another part's light >= 1, nodes at the centres of the tiles covering
    the frame."""
    nodes = np.asarray(field.nodes, np.float64)
    if not np.isfinite(nodes).all():
        raise InputError(f"{path}: the mixing field has non-finite values; measure it again "
                         "with plenocli crosstalk --mixing-out")
    diagonal = np.einsum("ckkab->ckab", nodes)
    off = np.abs(diagonal - 1)
    if off.max() > DIAGONAL_TOLERANCE:
        c, k, a, b = np.unravel_index(int(np.argmax(off)), off.shape)
        raise InputError(f"{path}: M[{field.views[k]}<-{field.views[k]}] of colour "
                         f"{field.colours[c]} is {diagonal[c, k, a, b]:.6g} at node ({a}, {b}); "
                         "a measured mixing has 1 on its diagonal (each view's own light): "
                         "the file was scaled or edited: measure it again")
    share = nodes.min()
    if share < -NEGATIVE_SHARE:
        raise InputError(f"{path}: the mixing field holds a share of light of {share:.3g}; a "
                         "view cannot record negative light from another pupil part "
                         "(whites measured above a wrong black?): measure it again")
    off = nodes * ~np.eye(field.n_views, dtype=bool)[None, :, :, None, None]
    if off.max() >= 1:
        c, k, j, a, b = np.unravel_index(int(np.argmax(off)), off.shape)
        raise InputError(f"{path}: M[{field.views[k]}<-{field.views[j]}] of colour "
                         f"{field.colours[c]} is {off[c, k, j, a, b]:.6g} at node ({a}, {b}): a "
                         "share of another part's light >= 1 (r >= 100 %) is not a measured "
                         "mixing (crosstalk refuses it): the file was edited: measure it again")
    _check_nodes(path, field)


def _check_nodes(path, field: MixingField) -> None:
    """Nodes are the centres of the square tiles that cover the frame (measure_mixing)."""
    rows, cols = field.shape
    axes = (("node_rows", np.asarray(field.node_rows, np.float64), rows),
            ("node_cols", np.asarray(field.node_cols, np.float64), cols))
    for name, axis, size in axes:
        if not (np.isfinite(axis).all() and axis.min() >= 0 and axis.max() <= size - 1):
            raise InputError(f"{path}: {name} {_short(axis)} lie outside the {cols} x {rows} "
                             "frame the mixing was measured on (nodes are tile centres); the "
                             "file was edited or damaged: measure it again")
    # the first of several tiles is whole: its centre is (tile - 1) / 2
    firsts = [axis[0] for _, axis, _ in axes if len(axis) > 1]
    tile = int(round(2 * firsts[0] + 1)) if firsts else max(rows, cols)
    for name, axis, size in axes:
        centres = tile_centres(size, max(tile, 1))
        if centres.shape != axis.shape or np.abs(centres - axis).max() > NODE_TOLERANCE_PX:
            raise InputError(f"{path}: {name} {_short(axis)} ({len(axis)} nodes) are not the "
                             f"centres of {tile} px tiles covering the {cols} x {rows} frame "
                             "(crosstalk --tile); the file was edited or damaged: measure it "
                             "again")


def _short(axis: np.ndarray) -> str:
    return f"[{axis.min():g} .. {axis.max():g}]" if axis.size else "[]"
