"""What plenocli logs inside a test, read by a handler of its own logger."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator


@contextlib.contextmanager
def plenocli_messages(level: int = logging.WARNING) -> Iterator[list[str]]:
    """The messages of ``level`` and above that plenocli logs inside the block (its logger does
    not propagate to pytest's capture, and its stream handler keeps the stderr of the first
    command a test ran)."""
    said: list[str] = []
    handler = logging.Handler(level)
    handler.emit = lambda record: said.append(record.getMessage())
    logging.getLogger("plenocli").addHandler(handler)
    try:
        yield said
    finally:
        logging.getLogger("plenocli").removeHandler(handler)
