"""Messages and progress on stderr. Silent with -q; progress bars only on a terminal."""

from __future__ import annotations

import contextlib
import contextvars
import logging
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import TypeVar

log = logging.getLogger("plenocli")
T = TypeVar("T")
_step = {"text": ""}  # what the running stage is doing now, shown by :func:`working`
_HELD: contextvars.ContextVar[list | None] = contextvars.ContextVar(
    "plenocli_held_messages", default=None)


class _HoldBack(logging.Filter):
    """Keep INFO messages logged inside :func:`messages_held` for later (warnings pass)."""

    def filter(self, record: logging.LogRecord) -> bool:
        held = _HELD.get()
        if held is None or record.levelno != logging.INFO:
            return True
        held.append(record)
        return False


log.addFilter(_HoldBack())


@contextlib.contextmanager
def messages_held() -> Iterator[list]:
    """Hold back the INFO messages (a stage's "IN -> OUT" line) logged in the block, in this
    thread: they report outputs that have not landed yet. The caller passes the list to
    :func:`release` once they have, and drops it when they did not (nothing was written)."""
    held: list = []  # log records, and actions of when_landed
    token = _HELD.set(held)
    try:
        yield held
    finally:
        _HELD.reset(token)


def when_landed(action: Callable[[], None]) -> None:
    """Run ``action`` (a command printing its report) once the outputs of the running stage
    have landed, after its messages; at once when no outputs are pending."""
    held = _HELD.get()
    if held is None:
        action()
    else:
        held.append(action)


def release(held: list) -> None:
    """Emit messages (and run actions) held by :func:`messages_held`, in the order they came."""
    for item in held:
        if isinstance(item, logging.LogRecord):
            log.handle(item)
        else:
            item()


def step(text: str) -> None:
    """Say what a long stage is doing now ("warping view 1 of 2, band 3 of 9"): the line of
    :func:`working` shows it beside the seconds elapsed; ``-v`` logs it."""
    if text != _step["text"]:
        _step["text"] = text
        if text:
            log.debug(text)


def configure(verbosity: int) -> None:
    """-1 quiet (errors only), 0 normal, 1 verbose (-v), 2 debug (-vv)."""
    level = {-1: logging.ERROR, 0: logging.INFO, 1: logging.DEBUG}.get(
        max(-1, min(verbosity, 1)), logging.INFO)
    log.setLevel(level)
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(_Printable("%(message)s"))
        log.addHandler(handler)
    log.propagate = False


def printable(text: str) -> str:
    """``text`` with the bytes of a file name that are not UTF-8 shown as the replacement
    character, as a terminal shows them (Python keeps them as surrogates: ``\\udcff``)."""
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


class _Printable(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        return printable(super().format(record))


def significant(value: float, digits: int = 2) -> str:
    """``value`` to ``digits`` significant digits, without an exponent (an uncertainty of
    4.7e-05 px is 0.000047, not the 0.0000 that four fixed decimals print)."""
    import numpy as np  # here: --help and the command table load this module without numpy

    return np.format_float_positional(float(value), precision=digits, fractional=False,
                                      trim="-")


def shown(path) -> str:
    """A path as the user would type it: relative to the working folder when inside it."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path.cwd()))
    except (ValueError, OSError, RuntimeError):  # RuntimeError: a symbolic-link loop
        return str(p)


def progress(items: Iterable[T], label: str, *, total: int | None = None) -> Iterator[T]:
    """Yield ``items``, drawing a one-line bar on stderr when it is a terminal and not quiet."""
    show = sys.stderr.isatty() and log.isEnabledFor(logging.INFO)
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    start, last = time.monotonic(), 0.0
    for k, item in enumerate(items, 1):
        yield item
        now = time.monotonic()
        if show and (now - last > 0.2 or k == total) and now - start > 1.0:
            last = now
            frac = f"{k}/{total}" if total else str(k)
            sys.stderr.write(f"\r{label}: {frac}  ({now - start:.1f} s)")
            sys.stderr.flush()
    if show and time.monotonic() - start > 1.0:
        sys.stderr.write("\n")


@contextlib.contextmanager
def working(label: str, *, after_s: float = 1.0, every_s: float = 0.5):
    """Show ``label: N.N s`` on stderr while the block runs, once it has taken ``after_s``,
    followed by the block's current :func:`step` ("warping view 1 of 2, band 7 of 48").

    For work with no natural steps (a registration, a large write). Only on a terminal and when
    not quiet; the line is cleared when the block ends.
    """
    show = sys.stderr.isatty() and log.isEnabledFor(logging.INFO)
    done = threading.Event()
    start = time.monotonic()
    _step["text"] = ""

    def tick():
        width = 0
        while not done.wait(every_s):
            elapsed = time.monotonic() - start
            if elapsed >= after_s:
                line = f"{label}: {elapsed:.1f} s  {_step['text']}"
                sys.stderr.write("\r" + line.ljust(width))
                sys.stderr.flush()
                width = max(width, len(line))
        if width:
            sys.stderr.write("\r" + " " * width + "\r")
            sys.stderr.flush()

    thread = threading.Thread(target=tick, daemon=True) if show else None
    if thread:
        thread.start()
    try:
        yield
    finally:
        done.set()
        if thread:
            thread.join()
