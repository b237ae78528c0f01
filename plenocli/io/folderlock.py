"""A lock held while a stage fills an output folder (``simulate``), or a pipeline run writes
its outputs (``plenocli run``).

A folder's files land together, and a run removes what the folder's earlier run wrote and it
did not write again (its record). Two runs filling one folder at the same moment each read
the record before the other landed, so each kept the other's files: a mixed set (the
files of two kinds beside one truth.json), both exit 0. The second run now waits for the
first: an exclusive ``flock`` on the folder's parent (the folder itself may not exist yet),
through the folder's real path, so a run given a symbolic link to it waits too. Two pipeline
runs writing the same files likewise: one's step read a file the other then replaced, and
the set they left contradicted its records. A process holding a folder's lock takes it again
freely (a run's simulate step inside the run's lock).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterable, Iterator
from pathlib import Path

from plenocli.progress import log, shown

_HELD: set[Path] = set()  # folders this process holds the lock of


@contextlib.contextmanager
def folders_locked(folders: Iterable[Path]) -> Iterator[None]:
    """Hold an exclusive lock on the parent of each folder of ``folders`` (made when
    missing, and removed again if empty when the block fails) for the block. Pass output
    files to lock the folders they go into."""
    made: list[Path] = []
    with contextlib.ExitStack() as stack:
        try:
            for parent in sorted({Path(os.path.realpath(f)).parent for f in folders}):
                if parent in _HELD:
                    continue
                missing = []
                at = parent
                while not at.exists() and at != at.parent:
                    missing.append(at)
                    at = at.parent
                parent.mkdir(parents=True, exist_ok=True)
                made.extend(missing)
                fd = os.open(parent, os.O_RDONLY)
                stack.callback(os.close, fd)  # closing releases the lock
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    log.info("waiting for another run writing into %s", shown(parent))
                    fcntl.flock(fd, fcntl.LOCK_EX)
                _HELD.add(parent)
                stack.callback(_HELD.discard, parent)
            yield
        except BaseException:
            for folder in made:  # deepest first
                with contextlib.suppress(OSError):
                    folder.rmdir()
            raise
