"""The names of the pages of a views TIFF: one rule for every command.

A page is named after its view (``A``, ``S01``, ``left``), or after its view and colour
(``left.R``, ``left.G``, ``left.B``: the colour pages of view ``left``); a single colour view is
pages ``R``, ``G``, ``B``. A focal sweep tags each page with its g (``left.R@g4``). A file whose
metadata names no page has pages ``view0``, ``view1``, ... (a page number alone stays a page
number: ``--views 1`` picks the second page whatever its name).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from plenocli.model.numbers import is_count

CHANNELS = ("R", "G", "B")
SWEEP_TAG = "@g"


def default_names(count: int) -> list[str]:
    """The names of ``count`` unnamed pages."""
    return [f"view{k}" for k in range(count)]


def colour_page(view: str, channel: str) -> str:
    """The name of colour ``channel`` of ``view`` (``left``, ``R`` -> ``left.R``)."""
    return f"{view}.{channel}"


def split_colour_page(name: str) -> tuple[str, str] | None:
    """(view, channel) of a colour page (``left.R`` -> (``left``, ``R``)), else None."""
    view, dot, channel = name.rpartition(".")
    return (view, channel) if dot and view and channel in CHANNELS else None


def view_of(name: str) -> str:
    """The view a page belongs to: its colour page's view, else the page's own name."""
    split = split_colour_page(name)
    return split[0] if split else name


def name_problem(name: str) -> str | None:
    """Why ``name``, given to name a page, would read as something else (a colour page, a sweep
    page, a page number), or None when it names a page of its own."""
    split = split_colour_page(name)
    if split:
        return f"{name!r} reads as colour page {split[1]} of a view {split[0]}"
    if SWEEP_TAG in name:
        return f"{name!r} holds {SWEEP_TAG!r}, the tag of a focal sweep's pages (left{SWEEP_TAG}4)"
    if is_count(name):
        return f"{name!r} reads as a page number"
    if not name.isprintable():  # a newline splits every one-line message naming the page
        return f"{name!r} holds a control character"
    return None


def refocused_part(meta: dict) -> str | None:
    """The pupil part a refocused file was made of (its metadata's ``refocus.view``: left,
    q01, ...), None for the whole pupil or a file refocus did not make."""
    part = (meta.get("refocus") or {}).get("view")
    if isinstance(part, str) and part != "full" and name_problem(part) is None:
        return part
    return None


def single_view_name(meta: dict, path) -> str:
    """The name of the one view a file holds: the pupil part refocus made it of
    (:func:`refocused_part`: a ``left.tif`` made with ``--view right`` is view ``right``), else
    the file's name without its suffix (``left.tif`` -> ``left``)."""
    return refocused_part(meta) or Path(path).stem


def pupil_views(names: list[str]) -> list[str]:
    """The views of a file's pages that are parts of the pupil, in page order: every view but
    the sum S of a dual-pixel file (S = A + B is no part of its own)."""
    views = list(dict.fromkeys(view_of(n) for n in names))
    if {"A", "B", "S"} <= set(views):
        views.remove("S")
    return views


def sweep_page(label: str, g: float) -> str:
    """A page of a focal sweep: ``label`` at g (``left.R``, 4 -> ``left.R@g4``)."""
    return f"{label}{SWEEP_TAG}{g_label(g)}"


def g_label(g: float) -> str:
    """How a sweep page names its g: 6 significant digits (``4``, ``3.5``, ``2.33333``)."""
    return f"{g:g}"


def split_sweep(name: str) -> tuple[str, str]:
    """(label, tag) of a page: ``left.R@g4`` -> (``left.R``, ``@g4``); no tag -> (name, "")."""
    label, at, tag = name.partition(SWEEP_TAG)
    return label, at + tag


@dataclass(frozen=True)
class ViewNames:
    """The page names of one file, and the views they make."""

    pages: tuple[str, ...]

    @classmethod
    def of(cls, meta: dict, count: int) -> ViewNames:
        """The names the metadata gives ``count`` pages, else the default names."""
        return cls(tuple(meta.get("views") or default_names(count)))

    @property
    def is_rgb(self) -> bool:
        """Pages ``R``, ``G``, ``B``: one colour view."""
        return self.pages == CHANNELS

    def colour_layout(self) -> tuple[list[str], list[str]] | None:
        """(views, channels) when every page is a colour page (``VIEW.C``) of two or more views
        with the same channels each, in page order; else None."""
        groups: dict[str, list[str]] = {}
        for name in self.pages:
            split = split_colour_page(name)
            if split is None:
                return None
            groups.setdefault(split[0], []).append(split[1])
        if len(groups) < 2:
            return None
        channels = next(iter(groups.values()))
        if any(c != channels for c in groups.values()):
            return None
        return list(groups), channels

    def groups(self, single: str) -> list[tuple[str, list[int]]]:
        """(view, page indices) in page order: the colour pages of a view together, any other
        page a view of its own; a file of one view (one page, or pages R, G, B) is ``single``
        (e.g. the file's stem)."""
        if self.is_rgb:
            return [(single, [0, 1, 2])]
        found: dict[str, list[int]] = {}
        for k, name in enumerate(self.pages):
            found.setdefault(view_of(name), []).append(k)
        if len(found) == 1:
            return [(single, next(iter(found.values())))]
        return list(found.items())

    def rgb_views(self) -> list[str] | None:
        """The views of pages ``VIEW.R, VIEW.G, VIEW.B`` per view in this order (``[""]`` for
        pages R, G, B), else None: how a picture shows the pages in colour."""
        if self.is_rgb:
            return [""]
        if not self.pages or len(self.pages) % 3:
            return None
        views = [view_of(self.pages[k]) for k in range(0, len(self.pages), 3)]
        expected = tuple(colour_page(v, c) for v in views for c in CHANNELS)
        return views if self.pages == expected else None

    def index(self, name: str) -> int | None:
        """The page called ``name``, or numbered ``name`` (a page number); None if neither."""
        if name in self.pages:
            return self.pages.index(name)
        if is_count(name) and int(name) < len(self.pages):
            return int(name)
        return None
