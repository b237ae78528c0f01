"""Validators of stage parameters: convert one value and check it, without click.

A value comes as the text a shell passes or as a YAML value (a number, a boolean, text); both
get the same checks and the same messages, which name the value as a shell would have typed it.
A bad value raises ValueError with the message the user reads (click prefixes it with
``Invalid value for '--option':``, and so does :func:`plenocli.pipeline.params.resolve`).
"""

from __future__ import annotations

import math
import os
from typing import Any

from plenocli.model.numbers import decimal, whole
from plenocli.model.views import name_problem

TIFF = (".tif", ".tiff")
RECORD_SUFFIX = ".plenocli.json"  # .NAME.plenocli.json: the record of NAME (pipeline/records)


def shell_text(value: Any) -> str:
    """A value as the shell word that carries it (``true``/``false`` for a boolean)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


class Validator:
    """Base: ``name`` is what ``--help`` shows (upper-cased), ``convert`` checks one value."""

    name = "text"
    is_path = False
    choices: tuple[str, ...] | None = None
    range_help: str | None = None  # shown in --help as [x>=0]

    def convert(self, value: Any) -> Any:
        return shell_text(value)


class Text(Validator):
    """Any text but blank (the stage parses it), without the spaces around it, as YAML and
    --set read a value (``--view ' S'`` is view S from the shell too): an empty value is not
    the default, as ``--smooth=`` is not (leave the option out for that)."""

    def convert(self, value: Any) -> str:
        text = shell_text(value)
        if not text.strip():
            raise ValueError(f"{text!r} is empty; give a value or leave the option out")
        return text.strip()


class PageNames(Validator):
    """Names for the pages a stage writes, comma separated: each distinct and read back as
    itself (not a colour page ``S.R``, a sweep page ``S@g3`` or a page number)."""

    def convert(self, value: Any) -> str:
        text = Text().convert(value)
        names = [n.strip() for n in text.split(",")]
        if not all(names):
            raise ValueError(f"{text!r} has an empty name; give names like S,A")
        for name in names:
            problem = name_problem(name)
            if problem:
                raise ValueError(f"{problem}; give names without .R/.G/.B, @g or digits "
                                 "alone, like S,A")
        if len(set(names)) < len(names):
            twice = next(n for n in names if names.count(n) > 1)
            raise ValueError(f"{twice!r} is given twice in {text!r}; give each page its own name")
        return ",".join(names)


class ViewList(Validator):
    """Views to read, by name or page number, comma separated: each named once (a view
    stacked twice is no second view), kept as read (``' A, B '`` is ``A,B``: the stages strip
    the names, and a record compares the resolved text). Whether they are in the file is the
    stage's check."""

    def convert(self, value: Any) -> str:
        text = Text().convert(value)
        names = [n.strip() for n in text.split(",") if n.strip()]
        if not names:
            raise ValueError(f"{text!r} names no view; give names like A,B or leave the "
                             "option out for all views")
        twice = next((n for n in names if names.count(n) > 1), None)
        if twice is not None:
            raise ValueError(f"view {twice!r} is named twice in {text!r}; name each view once")
        return ",".join(names)


class NameList(Validator):
    """One name or several, comma separated (kept as read: each name without the spaces
    around it, one per comma, so the count the stage checks is the count given)."""

    def convert(self, value: Any) -> str:
        return ",".join(n.strip() for n in Text().convert(value).split(","))


class Flag(Validator):
    """An on/off switch: true or false."""

    name = "boolean"

    def convert(self, value: Any) -> bool:
        if not isinstance(value, bool):
            raise ValueError(f"expected true or false, got {value!r}")
        return value


class Int(Validator):
    """A whole number, optionally bounded (both ends closed) and of one ``parity`` ("odd" or
    "even": a median window has a centre, a tile holds whole CFA cells)."""

    def __init__(self, min: int | None = None, max: int | None = None, *,
                 parity: str | None = None):
        if parity not in (None, "odd", "even"):
            raise ValueError(f"parity must be 'odd' or 'even', got {parity!r}")
        self.min, self.max, self.parity = min, max, parity
        self.name = "integer" if min is None and max is None else "integer range"
        self.bounds = None
        if min is not None and max is not None:
            self.bounds = f"{min}<=x<={max}"
        elif min is not None or max is not None:
            self.bounds = f"x>={min}" if min is not None else f"x<={max}"
        self.range_help = ", ".join(p for p in (self.bounds, parity) if p) or None

    def convert(self, value: Any) -> int:
        if isinstance(value, int) and not isinstance(value, bool):
            number = int(value)  # a plain int (a YAML number may print as its word, 010)
        else:
            try:
                number = whole(shell_text(value))
            except ValueError:
                raise ValueError(f"{shell_text(value)!r} is not a valid integer"
                                 f"{_in_digits(shell_text(value))}.") from None
        if (self.min is not None and number < self.min) or (
                self.max is not None and number > self.max):
            raise ValueError(f"{number} is not in the range {self.bounds}.")
        if self.parity and number % 2 != (self.parity == "odd"):
            raise ValueError(f"{number} is not {self.parity}.")
        return number


# batch --timeout: under 115 days, far past any capture and within what waits can be told
MAX_TIMEOUT_S = 1e7


class FiniteFloat(Validator):
    """A finite number, optionally bounded; ``min_open``/``max_open`` make a bound exclusive,
    e.g. ``FiniteFloat(min=0, min_open=True)`` for a strictly positive value. NaN and the
    infinities are refused (every comparison with NaN is false, so a range alone lets it in)."""

    name = "float"

    def __init__(self, min: float | None = None, max: float | None = None, *,
                 min_open: bool = False, max_open: bool = False):
        self.min, self.max, self.min_open, self.max_open = min, max, min_open, max_open

    def convert(self, value: Any) -> float:
        if isinstance(value, bool):
            raise ValueError(f"{shell_text(value)!r} is not a number")
        try:
            number = float(value) if isinstance(value, (int, float)) else decimal(value)
        except (TypeError, ValueError):
            raise ValueError(f"{shell_text(value)!r} is not a number") from None
        if not math.isfinite(number):
            raise ValueError(f"{shell_text(value)!r} is not a finite number")
        low_bad = self.min is not None and (number <= self.min if self.min_open
                                            else number < self.min)
        high_bad = self.max is not None and (number >= self.max if self.max_open
                                             else number > self.max)
        if low_bad or high_bad:
            raise ValueError(f"{number:g} is not in the range {self.describe()}")
        return number

    def describe(self) -> str:
        parts = []
        if self.min is not None:
            parts.append(f"x{'>' if self.min_open else '>='}{self.min:g}")
        if self.max is not None:
            parts.append(f"x{'<' if self.max_open else '<='}{self.max:g}")
        return " and ".join(parts) or "of finite numbers"


class Choice(Validator):
    """One of ``choices`` (matched ignoring case when ``case_sensitive`` is False)."""

    name = "choice"

    def __init__(self, choices, *, case_sensitive: bool = True):
        self.choices = tuple(choices)
        self.case_sensitive = case_sensitive

    def convert(self, value: Any) -> str:
        text = shell_text(value)
        for choice in self.choices:
            if text == choice or (not self.case_sensitive and text.lower() == choice.lower()):
                return choice
        listed = ", ".join(repr(c) for c in self.choices)
        raise ValueError(f"{text!r} is not one of {listed}.")


class RowsCols(Validator):
    """A size ROWSxCOLS of positive whole numbers, e.g. 2000x2000 (kept as that text)."""

    name = "ROWSxCOLS"

    def convert(self, value: Any) -> str:
        text = shell_text(value).strip().lower()
        rows, sep, cols = text.partition("x")
        size = _positive(rows), _positive(cols)
        if not (sep and all(size)):
            raise ValueError(f"{shell_text(value)!r} is not ROWSxCOLS (e.g. 2000x2000)")
        return f"{size[0]}x{size[1]}"


def _in_digits(word: str) -> str:
    """For a whole value written as a decimal number ('1e2', '10.0'): how to write it."""
    try:
        number = decimal(word)
    except ValueError:
        return ""
    return f" (a whole number is written in digits: {int(number)})" if (
        math.isfinite(number) and number.is_integer()) else ""


def _positive(word: str) -> int | None:
    """A positive whole number written in digits ('+64', '064'), else None."""
    try:
        number = whole(word)
    except ValueError:
        return None
    return number if number > 0 else None


class SensorSize(Validator):
    """A sensor size: one positive whole number (a square) or ROWSxCOLS (kept as that text)."""

    name = "N|ROWSxCOLS"

    def convert(self, value: Any) -> str:
        text = shell_text(value).strip()
        if _positive(text):
            return str(_positive(text))
        try:
            return RowsCols().convert(text)
        except ValueError:
            raise ValueError(f"{shell_text(value)!r} is not one positive whole number or "
                             "ROWSxCOLS (e.g. 256 or 192x256)") from None


class InputFile(Validator):
    """A file a stage reads. A folder is a usage error, like any value of the wrong kind;
    whether the file is there and can be read is the reader's to say (exit 1 with the reason),
    as for a file that turns out to be damaged."""

    name = "file"
    is_path = True

    def convert(self, value: Any) -> str:
        return _path_word(value, folder=False)


class OutputFile(Validator):
    """A file a stage writes, whose name must end in one of ``suffixes`` (any case; any name
    when none is given): a name saying another format (a preview named .jpg, frames named .png)
    would hold what it does not say, and the make-style runner reads outputs by their suffix."""

    name = "file"
    is_path = True

    def __init__(self, *suffixes: str, formats: str | None = None):
        self.suffixes = suffixes
        # what the file is written as, in words (the first suffix's format when not given)
        self.formats = formats or (suffixes[0][1:].upper() if suffixes else "")

    def convert(self, value: Any) -> str:
        path = _output_word(value, folder=False)
        name = os.path.basename(path)
        if self.suffixes and name.lower() in self.suffixes:  # splitext: '.tif' is all stem
            raise ValueError(f"{path!r} has no name before its suffix; give one, e.g. "
                             f"out{self.suffixes[0]}")
        if self.suffixes and os.path.splitext(path)[1].lower() not in self.suffixes:
            ending = (" or ".join(self.suffixes) if len(self.suffixes) < 3
                      else ", ".join(self.suffixes[:-1]) + " or " + self.suffixes[-1])
            raise ValueError(f"{path!r} is written as {self.formats}; give a name ending in "
                             f"{ending}")
        return path


class OutputFolder(Validator):
    """A folder a stage writes into (made when missing); an empty name would be the current
    folder, which no one means."""

    name = "directory"
    is_path = True

    def convert(self, value: Any) -> str:
        return _output_word(value, folder=True)


def _output_word(value: Any, *, folder: bool) -> str:
    """An output path as :func:`_path_word`, without control characters: a newline in a name
    would split every one-line message that names it (and most scripts that list the files)."""
    path = _path_word(value, folder=folder)
    control = next((c for c in path if ord(c) < 32 or ord(c) == 127), None)
    if control is not None:
        raise ValueError(f"{path!r} holds a control character ({control!r}); give a name "
                         "without one")
    name = os.path.basename(os.path.normpath(path))
    if name.startswith(".") and name.endswith(RECORD_SUFFIX):
        raise ValueError(f"{path!r} is named as a plenocli record (.NAME{RECORD_SUFFIX} says "
                         "how NAME was made, and the runner reads it); choose another name")
    return path


def _path_word(value: Any, *, folder: bool) -> str:
    """A path given as a word: not empty (which would be the current folder or no file), and
    not a folder where a file is meant, nor a file where a folder is."""
    path = shell_text(value)
    if path == "":
        raise ValueError(f"the {'folder' if folder else 'file'} name is empty")
    if folder and os.path.exists(path) and not os.path.isdir(path):
        raise ValueError(f"Directory {path!r} is a file.")
    if not folder and os.path.isdir(path):
        raise ValueError(f"File {path!r} is a directory.")
    return path
