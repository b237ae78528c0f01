"""Numbers written as words (a shell argument, an item of a list or a range): decimal forms in
ASCII only, as YAML 1.2's core schema reads them in a config. Python's ``int`` and ``float``
also take ``4_0`` (40) and the digits of every script (``٣`` is 3), so a typo or a pasted
character would become a number."""

from __future__ import annotations

import re

_DECIMAL = re.compile(r"[-+]?(\d+(\.\d*)?|\.\d+)([eE][-+]?\d+)?", re.ASCII)
_WHOLE = re.compile(r"[-+]?\d+", re.ASCII)
# taken, so that the callers refuse them by name ("not a finite number")
_NOT_FINITE = re.compile(r"[-+]?\.?(inf|infinity|nan)", re.ASCII | re.IGNORECASE)


def decimal(word: str) -> float:
    """The number of a decimal word ('2', '-0.5', '3e-4', and 'inf' or 'nan'); ValueError
    for any other word."""
    text = str(word).strip()
    if _DECIMAL.fullmatch(text):
        return float(text)
    if _NOT_FINITE.fullmatch(text):
        return float(text.replace(".", ""))
    raise ValueError(f"{word!r} is not a decimal number")


def whole(word: str) -> int:
    """The integer of a word of ASCII digits (optionally signed); ValueError otherwise."""
    text = str(word).strip()
    if _WHOLE.fullmatch(text):
        return int(text)
    raise ValueError(f"{word!r} is not a whole number")


def is_count(word: str) -> bool:
    """Whether a word is ASCII digits alone (a page number, a size)."""
    return bool(re.fullmatch(r"\d+", word, re.ASCII))


def number_word(value: float) -> str:
    """The shortest decimal word that reads back as exactly ``value`` ('2' for 2.0, '0.5',
    '1e-05'): how a resolved number is recorded (``:g`` would keep 6 digits and change it)."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text
