"""Atomic writes: a failed or interrupted stage never leaves a half-written file."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from plenocli.errors import InputError


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, protect: tuple = ()) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only on success.

    The temporary file lives in the destination folder so that the final rename is atomic on
    POSIX file systems. On any exception (or Ctrl-C) the temporary file is removed and the
    destination is left as it was. ``protect`` lists input files that must never be overwritten.
    """
    dest = Path(path)
    for other in protect:
        if other is not None and Path(other).exists() and dest.exists():
            if os.path.samefile(other, dest):
                raise InputError(
                    f"output {dest} is also an input; choose another output path "
                    "(plenocli never overwrites its inputs)"
                )
    if dest.is_dir():
        raise InputError(f"output {dest} is a folder; give a file name")
    dest.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".part", dir=dest.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, 0o644)
        os.replace(tmp, dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes(path: str | os.PathLike, data: bytes, *, protect: tuple = ()) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path, protect=protect) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | os.PathLike, text: str, *, protect: tuple = ()) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes(path, text.encode("utf-8"), protect=protect)
