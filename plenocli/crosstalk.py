"""Sub-aperture cross-talk: how much light meant for one view lands on the others.

A capture of a white target is taken with every part of the pupil masked except one (dual-pixel:
one half; quad-pixel: one quarter; Raytrix: the left or right refocused view with a mask of
width m). Ideally only the intended view then receives light. The cross-talk ratio is

    r = max over the other views v of  flux(v) / flux(intended)

(the paper: 13 % for the real quad-pixel lens, about 3 % with a cross mask; Canon dual-pixel
about 50 %). Flux is summed over pixels where every view is finite (NaN = masked value, e.g. B
where S clipped). r is reported globally, as a map over tiles of the frame, and per colour when
the views are Bayer mosaics.

With one masked white per pupil part, ``measure_mixing`` gives the whole mixing matrix M per
tile and colour (view k records sum_j M_kj T_j; M_jj = 1), which ``plenocli.unmix`` inverts.
r is then max over k != j of M_kj / M_jj.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy import ndimage

from plenocli.model.cfa import check_pattern
from plenocli.model.mixing import MixingField, tile_centres


def _colour_masks(shape: tuple[int, int], cfa: str | None) -> dict[str, np.ndarray]:
    """Boolean masks of each colour of a 2 x 2 pattern (greens pooled); {} for no mosaic."""
    if not cfa:
        return {}
    masks: dict[str, np.ndarray] = {}
    for k, colour in enumerate(check_pattern(cfa)):
        m = masks.setdefault(colour, np.zeros(shape, bool))
        m[k // 2::2, k % 2::2] = True
    return masks


def check_tile(tile_px: int, shape: tuple[int, ...]) -> None:
    """ValueError unless ``tile_px`` is even, >= 2 and no longer than the image's longer side."""
    if tile_px < 2 or tile_px % 2:
        raise ValueError(f"tile_px must be an even number >= 2, got {tile_px}")
    if tile_px > max(shape[-2:]):
        raise ValueError(f"tile {tile_px} px is larger than the {shape[-1]} x {shape[-2]} "
                         "image; choose a tile of a few dozen pixels (--tile 64)")


def _tile_sums(values: np.ndarray, tile_px: int) -> np.ndarray:
    """Sum of (rows, cols) ``values`` over tile_px x tile_px tiles (edge tiles partial)."""
    check_tile(tile_px, values.shape)
    rows, cols = values.shape
    n_r, n_c = -(-rows // tile_px), -(-cols // tile_px)
    padded = np.zeros((n_r * tile_px, n_c * tile_px), np.float64)
    padded[:rows, :cols] = values
    return padded.reshape(n_r, tile_px, n_c, tile_px).sum(axis=(1, 3))


def _ratio(others: np.ndarray, main: np.ndarray) -> np.ndarray:
    """max over the first axis of others / main; NaN where main has no positive flux."""
    with np.errstate(divide="ignore", invalid="ignore"):
        r = others.max(axis=0) / main
    return np.where(main > 0, r, np.nan)


def crosstalk_ratio(views: np.ndarray, *, intended: int | None = None, tile_px: int = 64,
                    cfa: str | None = None, min_valid_fraction: float = 0.25) -> dict:
    """Cross-talk ratio r of one masked-pupil white capture, globally, per tile and per colour.

    Parameters
    ----------
    views : (V, rows, cols) views of a white target, V >= 2, linear signal above black (DN or
        any unit). NaN marks masked values; those pixels are left out of every sum.
    intended : index of the view whose pupil part was open; None = the view with the most flux.
    tile_px : side of the square tiles of the map (px; even, so a tile holds whole CFA cells).
    cfa : 2 x 2 Bayer pattern at pixel (0, 0) (e.g. "RGGB") for per-colour ratios; None = none.
    min_valid_fraction : tiles with fewer valid pixels than this fraction are NaN in the map.

    Returns
    -------
    dict with ``r`` (global), ``r_per_view`` (name = view index), ``intended``, ``map``
    ((n_tile_rows, n_tile_cols) float64 array of r, NaN where undefined), ``map_min``/``map_max``,
    ``tile_px``, ``per_colour`` ({colour: {"r": float, "map": array}}), ``valid_fraction``.
    """
    data = np.asarray(views, dtype=np.float64)
    if data.ndim != 3 or data.shape[0] < 2:
        raise ValueError(f"cross-talk needs a stack of at least 2 views (V, rows, cols), got "
                         f"shape {data.shape}")
    n_views, rows, cols = data.shape
    if tile_px < 2 or tile_px % 2:
        raise ValueError(f"tile_px must be an even number >= 2, got {tile_px}")
    valid = np.isfinite(data).all(axis=0)
    if not valid.any():
        raise ValueError("no pixel is finite in every view; nothing to measure")
    clean = np.where(valid, data, 0.0)
    flux = clean.reshape(n_views, -1).sum(axis=1)
    if intended is None:
        intended = int(np.argmax(flux))
    if not 0 <= intended < n_views:
        raise ValueError(f"intended view {intended} out of range for {n_views} views")
    if flux[intended] <= 0:
        raise ValueError(f"the intended view {intended} received no light (flux "
                         f"{flux[intended]:.3g}); is this a white-target capture above black?")
    others = [k for k in range(n_views) if k != intended]
    r_per_view = {k: float(flux[k] / flux[intended]) for k in others}

    def tile_map(select: np.ndarray, possible: np.ndarray) -> np.ndarray:
        """r per tile over the ``select`` pixels; NaN where too few of ``possible`` are valid."""
        count = _tile_sums(select.astype(np.float64), tile_px)
        main = _tile_sums(np.where(select, clean[intended], 0.0), tile_px)
        rest = np.stack([_tile_sums(np.where(select, clean[k], 0.0), tile_px) for k in others])
        full = _tile_sums(possible.astype(np.float64), tile_px)
        return np.where(count >= min_valid_fraction * full, _ratio(rest, main), np.nan)

    r_map = tile_map(valid, np.ones((rows, cols), bool))
    per_colour = {}
    for colour, mask in _colour_masks((rows, cols), cfa).items():
        sel = mask & valid
        main = clean[intended][sel].sum()
        rest = np.array([clean[k][sel].sum() for k in others])
        per_colour[colour] = {"r": float(rest.max() / main) if main > 0 else float("nan"),
                              "map": tile_map(sel, mask)}
    # a ratio of a few scattered pixels is not the capture's: r is measured where some tile
    # is known well enough to map it, in every colour
    for name, tiles in [("", r_map)] + [(f" of colour {c}", v["map"])
                                        for c, v in per_colour.items()]:
        if not np.isfinite(tiles).any():
            raise ValueError(
                f"too few pixels{name} are known in every view to measure r: "
                f"{int(valid.sum())} of {valid.size} ({100 * valid.mean():.2g} %), and no "
                f"{tile_px} px tile has {100 * min_valid_fraction:.0f} % of its pixels{name} "
                "known; measure on a white whose pixels are known (not clipped or masked)")
    finite = r_map[np.isfinite(r_map)]
    return {
        "r": max(r_per_view.values()),
        "r_per_view": r_per_view,
        "intended": intended,
        "map": r_map,
        "map_min": float(finite.min()) if finite.size else float("nan"),
        "map_max": float(finite.max()) if finite.size else float("nan"),
        "tile_px": tile_px,
        "per_colour": per_colour,
        "valid_fraction": float(valid.mean()),
    }


def mask_width_sweep(make_views: Callable[[float], tuple[np.ndarray, np.ndarray]],
                     mask_widths: Sequence[float], *, intended: str = "left",
                     tile_px: int = 64) -> list[dict]:
    """Cross-talk of Raytrix left/right refocused views as the central mask width m grows.

    Parameters
    ----------
    make_views : callable m -> (left, right), two (rows, cols) images of a white target
        refocused with mask width m (px); e.g. a wrapper around ``plenocli.refocus.refocus``.
    mask_widths : the widths m (px) to try, e.g. (0, 1, 2, 3).
    intended : which view's pupil half was open in the capture: "left" or "right".

    Returns
    -------
    One dict per width: ``mask_width``, ``r``, ``map_min``, ``map_max``, ``flux_intended``
    (mean signal of the intended view: the light the mask costs).
    """
    if intended not in ("left", "right"):
        raise ValueError(f"intended must be 'left' or 'right', got {intended!r}")
    if not len(mask_widths):
        raise ValueError("mask_widths is empty")
    results = []
    for m in mask_widths:
        if m < 0:
            raise ValueError(f"mask widths must be >= 0, got {m}")
        left, right = make_views(float(m))
        stack = np.stack([np.asarray(left, np.float64), np.asarray(right, np.float64)])
        try:
            res = crosstalk_ratio(stack, intended=0 if intended == "left" else 1,
                                  tile_px=tile_px)
        except ValueError as err:
            raise ValueError(f"mask width {m:g} px: {err} (a narrower mask keeps more of each "
                             "micro-image)") from err
        main = stack[res["intended"]]
        results.append({"mask_width": float(m), "r": res["r"], "map_min": res["map_min"],
                        "map_max": res["map_max"],
                        "flux_intended": float(np.nanmean(main))})
    return results


def refocus_mask_sweep(frame: np.ndarray, grid, mask_widths: Sequence[float], *,
                       s: float = 0.2, g: float = 4.0, intended: str = "left",
                       tile_px: int = 64) -> list[dict]:
    """``mask_width_sweep`` of a Raytrix white ``frame`` (rows, cols) with one pupil half
    masked: left and right views refocused (``plenocli.refocus.refocus``, scale ``s``,
    parameter ``g``) with the lens ``grid`` (a ``LensGrid`` in the frame's pixels)."""
    from plenocli.refocus import refocus  # numba kernels: loaded only for a sweep

    def make_views(m: float) -> tuple[np.ndarray, np.ndarray]:
        left, _ = refocus(frame, grid, s=s, g=g, view="left", mask_width=m)
        right, _ = refocus(frame, grid, s=s, g=g, view="right", mask_width=m)
        return left, right

    return mask_width_sweep(make_views, mask_widths, intended=intended, tile_px=tile_px)


def measure_mixing(captures: Sequence[np.ndarray], *, intended: Sequence[int],
                   views: Sequence[str], tile_px: int = 64, colour_pattern=None,
                   colours: Sequence[str] = ("L",), min_valid_fraction: float = 0.25
                   ) -> MixingField:
    """The mixing-matrix field M from one masked-pupil white per pupil part.

    In capture j only pupil part ``intended[j]`` is open, so view k records
    ``M_k,intended W`` with W that part's white: per tile and colour, M_k,intended is the flux of
    view k over the flux of the intended view (the paper's ratio, tile by tile), and
    ``M_jj = 1``. Node positions are the tile centres; ``plenocli.unmix`` interpolates between
    them.

    Parameters
    ----------
    captures : V arrays (V, rows, cols), one per pupil part, linear above black; NaN = masked.
    intended : the open part (view index) of each capture: a permutation of 0..V-1.
    views : the V view names.
    tile_px : tile side (px; even, so a tile holds whole CFA cells).
    colour_pattern : 2 x 2 indices into ``colours`` of a Bayer mosaic; None = one colour.
    colours : names of the colour planes.
    min_valid_fraction : tiles with fewer valid pixels are filled from the nearest good tile.

    Returns
    -------
    MixingField with nodes (colours, V, V, n_tile_rows, n_tile_cols).
    """
    n_views = len(views)
    if len(captures) != n_views or sorted(int(k) for k in intended) != list(range(n_views)):
        raise ValueError(f"the mixing needs one masked white per pupil part: {n_views} captures "
                         f"with intended views {list(range(n_views))} in any order, got "
                         f"{len(captures)} with {list(intended)}")
    if tile_px < 2 or tile_px % 2:
        raise ValueError(f"tile_px must be an even number >= 2, got {tile_px}")
    shapes = {np.shape(c) for c in captures}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3 or next(iter(shapes))[0] != n_views:
        raise ValueError(f"the masked whites must all be ({n_views}, rows, cols) views of one "
                         f"size, got shapes {sorted(shapes)}")
    rows, cols = next(iter(shapes))[1:]
    pattern = np.zeros((2, 2), np.int64) if colour_pattern is None else \
        np.asarray(colour_pattern, np.int64).reshape(2, 2)
    colour_of = np.tile(pattern, (-(-rows // 2), -(-cols // 2)))[:rows, :cols]
    n_r, n_c = -(-rows // tile_px), -(-cols // tile_px)
    nodes = np.full((len(colours), n_views, n_views, n_r, n_c), np.nan)
    for capture, j in zip(captures, intended, strict=True):
        data = np.asarray(capture, np.float64)
        valid = np.isfinite(data).all(axis=0)
        for c in range(len(colours)):
            plane = colour_of == c
            sel = plane & valid
            enough = _tile_sums(sel.astype(np.float64), tile_px) >= \
                min_valid_fraction * _tile_sums(plane.astype(np.float64), tile_px)
            flux = np.stack([_tile_sums(np.where(sel, data[k], 0.0), tile_px)
                             for k in range(n_views)])
            main = flux[j]
            good = enough & (main > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                nodes[c, :, j] = np.where(good, flux / main, np.nan)
            if not enough.any():
                raise ValueError(f"masked white of view {views[j]}: no {tile_px} px tile has "
                                 f"{100 * min_valid_fraction:.0f} % of its colour {colours[c]} "
                                 f"pixels known in every view ({100 * valid.mean():.2g} % of "
                                 "all pixels are); use a white whose pixels are known (not "
                                 "clipped or masked)")
            if not good.any():
                raise ValueError(f"masked white of view {views[j]}: no tile of colour "
                                 f"{colours[c]} has light in view {views[j]}; is it the capture "
                                 "with that pupil part open?")
    nodes = _fill_from_nearest(nodes)
    _check_open_parts(nodes, views, colours)
    centre_r, centre_c = tile_centres(rows, tile_px), tile_centres(cols, tile_px)
    for c in range(len(colours)):
        # A colour's pixels sit off the tile centre (red of RGGB by half a pixel up and left):
        # move its values to the centre along the field's gradient.
        cells = np.argwhere(pattern == c)
        if len(cells) and colour_pattern is not None:
            off_r, off_c = cells.mean(axis=0) - 0.5
            nodes[c] = _shift_nodes(nodes[c], centre_r, centre_c, off_r, off_c)
    return MixingField(nodes.astype(np.float32), centre_r, centre_c, (rows, cols), tuple(views),
                       tuple(colours))



def measure_mixing_colours(captures: Sequence[np.ndarray], *, intended: Sequence[int],
                           views: Sequence[str], colours: Sequence[str], tile_px: int = 64,
                           colour_pattern=None) -> MixingField:
    """``measure_mixing`` of masked whites held as (V, C, rows, cols): one mosaic per view
    (C = 1, ``colour_pattern`` its Bayer cells) or C colour planes per view, measured alone."""
    planes = np.shape(captures[0])[1]
    if planes == 1:
        return measure_mixing([np.asarray(c)[:, 0] for c in captures], intended=intended,
                              views=views, tile_px=tile_px, colour_pattern=colour_pattern,
                              colours=colours)
    fields = [measure_mixing([np.asarray(c)[:, k] for c in captures], intended=intended,
                             views=views, tile_px=tile_px, colours=[colours[k]])
              for k in range(planes)]
    first = fields[0]
    return MixingField(np.concatenate([f.nodes for f in fields]), first.node_rows,
                       first.node_cols, first.shape, tuple(views), tuple(colours))

def _check_open_parts(nodes: np.ndarray, views: Sequence[str], colours: Sequence[str]) -> None:
    """Every tile's open part is its brightest view: a share M_kj >= 1 (r >= 100 %) is a tile
    where the mask let the other part through, and no mixing unmix should invert."""
    off = nodes * ~np.eye(len(views), dtype=bool)[None, :, :, None, None]
    if off.max() >= 1:
        c, k, j, a, b = np.unravel_index(int(np.argmax(off)), off.shape)
        raise ValueError(f"masked white of view {views[j]}: view {views[k]} records "
                         f"{100 * off[c, k, j, a, b]:.0f} % of the open part's light in tile "
                         f"({a}, {b}) of colour {colours[c]} (r >= 100 %): not a white with only "
                         "that part open; check --intended and the mask")


def _shift_nodes(values: np.ndarray, node_rows: np.ndarray, node_cols: np.ndarray,
                 off_r: float, off_c: float) -> np.ndarray:
    """Values (..., n_r, n_c) measured at node + (off_r, off_c), moved to the nodes (first
    order)."""
    out = values.copy()
    if len(node_rows) > 1:
        out -= off_r * np.gradient(values, node_rows, axis=-2)
    if len(node_cols) > 1:
        out -= off_c * np.gradient(values, node_cols, axis=-1)
    return out


def _fill_from_nearest(nodes: np.ndarray) -> np.ndarray:
    """NaN nodes (tiles without enough light) take the value of the nearest measured tile."""
    bad = ~np.isfinite(nodes).all(axis=(0, 1, 2))
    if not bad.any():
        return nodes
    _, (ir, ic) = ndimage.distance_transform_edt(bad, return_indices=True)
    filled = nodes[..., ir, ic]
    return np.where(np.isfinite(nodes), nodes, filled)


def mixing_ratio(mixing: MixingField) -> dict:
    """The paper's r from M: max over k != j of M_kj / M_jj, over the field's nodes (``r_max``)
    and of the node mean (``r_mean``), per colour and per (k, j) pair."""
    nodes = np.asarray(mixing.nodes, np.float64)
    diag = np.stack([nodes[:, j, j] for j in range(mixing.n_views)], axis=1)[:, None]
    ratio = nodes / diag
    off = ~np.eye(mixing.n_views, dtype=bool)
    per_colour = {c: float(ratio[i][off].max()) for i, c in enumerate(mixing.colours)}
    pairs = {f"{mixing.views[k]}<-{mixing.views[j]}": float(ratio[:, k, j].mean())
             for k in range(mixing.n_views) for j in range(mixing.n_views) if k != j}
    return {"r_max": max(per_colour.values()), "r_mean": max(pairs.values()),
            "r_max_per_colour": per_colour, "mean_per_pair": pairs}
