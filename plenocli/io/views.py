"""Named views of a views TIFF: pick them by name, group colour pages, read masked whites.

A views TIFF names its pages in the metadata (``views``): one page per view (``A``, ``B``,
``S00``), possibly one mosaic each, or one page per view and colour (``left.R``, ``left.G``...).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.io.framing import active_area
from plenocli.model.views import CHANNELS, ViewNames, colour_page, split_sweep


@dataclass(frozen=True)
class ColourViews:
    """Views of one capture as (V, C, rows, cols) float64 over the active area.

    ``layout`` is "channels" (C colour pages per view), "cfa" (one Bayer mosaic per view,
    C = 1, ``cfa`` its 2 x 2 pattern) or "mono"; ``colours`` names the colour planes."""

    data: np.ndarray
    names: list[str]
    colours: list[str]
    layout: str
    cfa: str | None

    def colour_pattern(self) -> np.ndarray | None:
        """2 x 2 indices into ``colours`` of the Bayer pattern (None: not a mosaic)."""
        if self.layout != "cfa":
            return None
        return np.array([self.colours.index(ch) for ch in self.cfa.upper()]).reshape(2, 2)

    def same_kind(self, other: ColourViews) -> bool:
        return (self.names, self.colours, self.layout, self.cfa, self.data.shape) == (
            other.names, other.colours, other.layout, other.cfa, other.data.shape)


def select_views(data: np.ndarray, meta: dict, views: str | None) -> tuple[np.ndarray, list[str]]:
    """Pages of ``data`` named in ``views`` ("A,B"; names from the metadata, or page numbers)."""
    pages = ViewNames.of(meta, data.shape[0])
    names = list(pages.pages)
    if not views:
        return data, names
    idx = []
    for name in _wanted(views):
        k = pages.index(name)
        if k is None:
            raise InputError(f"view {name!r} is not in the input (views: {','.join(names)}); "
                             "pass --views with names from that list")
        idx.append(k)
    check_named_once([names[k] for k in idx])
    return data[idx], [names[k] for k in idx]


def read_colour_views(path: str, views: str | None) -> ColourViews:
    """The views of one file named in ``views`` (all when None), grouped by colour."""
    data, meta = tiffio.read_image(path)
    framing = active_area(meta, data.shape[1:])
    data, cfa = framing.crop(data), framing.cfa
    pages = ViewNames.of(meta, data.shape[0])
    swept = sorted({split_sweep(n)[1] for n in pages.pages} - {""})
    if swept:
        raise InputError(f"{path}: its pages are planes of a focal sweep ({', '.join(swept[:3])}"
                         f"{', ...' if len(swept) > 3 else ''}), one view at several g, not pupil "
                         "views; refocus each view at one g (refocus --view left/right --g G)")
    if pages.is_rgb:   # pages R, G, B: the colours of one view (named after the file), not three
        name = Path(path).stem
        if views and _wanted(views) != [name]:
            raise InputError(f"{path}: pages R, G, B are the colours of one view ({name}), "
                             "not views; give one file per view")
        return ColourViews(data[None].astype(np.float64), [name], list(CHANNELS), "channels",
                           None)
    grouped = pages.colour_layout()
    if grouped:
        names, channels = grouped
        if views:
            missing = [v for v in _wanted(views) if v not in names]
            if missing:
                raise InputError(f"{path}: view {missing[0]!r} is not in the input (views: "
                                 f"{','.join(names)}); pass --views with names from that list")
            names = _wanted(views)
            check_named_once(names)
        index = {n: k for k, n in enumerate(pages.pages)}
        stack = np.stack([[data[index[colour_page(v, c)]] for c in channels] for v in names])
        return ColourViews(stack.astype(np.float64), names, channels, "channels", None)
    chosen, names = select_views(data, meta, views)
    colours = sorted(set(cfa.upper()), key="RGB".index) if cfa else ["L"]
    return ColourViews(chosen[:, None].astype(np.float64), names, colours,
                       "cfa" if cfa else "mono", cfa)


def read_masked_whites(inputs: list[str], views: str | None
                       ) -> tuple[list[ColourViews], list[str]]:
    """The masked whites and a label for each. Files of one view each (refocused left/right
    images) come V to a masked white, in the order ``views`` names them."""
    single = all(_one_view(tiffio.read_meta(p).get("views")) for p in inputs)
    if not single:
        return [read_colour_views(p, views) for p in inputs], list(inputs)
    names = _wanted(views or "")
    if len(names) < 2 or len(inputs) != len(names) ** 2:
        raise InputError(f"each input holds one view: name the views with --views (e.g. "
                         f"left,right) and give that many files per masked white, in that order "
                         f"({len(inputs)} files given)")
    loaded, labels = [], []
    for k in range(0, len(inputs), len(names)):
        group = inputs[k:k + len(names)]
        parts = [read_colour_views(p, None) for p in group]
        if len({p.data.shape for p in parts}) != 1:
            raise InputError(f"{', '.join(group)}: the views of one masked white differ in size")
        first = parts[0]
        loaded.append(ColourViews(np.concatenate([p.data for p in parts]), names, first.colours,
                                  first.layout, first.cfa))
        labels.append("+".join(group))
    return loaded, labels


def _one_view(names: list | None) -> bool:
    """A file of one view: one page, or the pages R, G, B of one colour view."""
    return names is not None and (len(names) == 1 or ViewNames(tuple(names)).is_rgb)


def check_black_subtracted(path: str, meta: dict, why: str) -> None:
    """InputError unless the black level of ``path`` is gone (``plenocli bias``): the stages
    that take ratios of light (flat, crosstalk, unmix), or drop the level from their output
    (sai, refocus), would count it as light. ``why`` ends the message."""
    try:
        black = np.asarray(meta.get("black_level") or 0, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{path}: black_level in the metadata is not a list of numbers; "
                         "decode and bias the capture again") from None
    if np.any(black != 0):
        raise InputError(f"{path}: black level {np.nanmax(black):g} DN not subtracted yet; run "
                         f"plenocli bias first ({why})")


def check_named_once(names: list[str]) -> None:
    """A --views list names each view once (a view stacked twice is no second view)."""
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError(f"--views names view {twice[0]!r} twice; name each view once")


def _wanted(views: str) -> list[str]:
    return [v.strip() for v in views.split(",") if v.strip()]

