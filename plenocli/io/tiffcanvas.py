"""A result TIFF filled in place: its pages memory-mapped while a stage computes them.

A panorama is the largest image plenocli makes (1.4 GB of float32 at the 5D Mark IV's size).
Computed into an array and then written, its pixels are touched twice in fresh memory (the
array, then the file's pages); on a virtual machine the page faults alone cost more than the
blend. Here the stage computes straight into the output file's pages, band by band, and the
metadata is written once the pixels are done. The file is the same as :func:`tiffio.write_image`
writes (one float32 page per view, the JSON description on the first page), made atomically
beside its destination, and checked as that function checks a result before it lands.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import tifffile

from plenocli import __version__
from plenocli.io.atomic import atomic_path
from plenocli.io.tiffio import check_result, describe


class ImageCanvas:
    """The pages of a float32 result TIFF, memory-mapped: :meth:`allocate` makes the file and
    returns its pixels (views, rows, cols), zero-filled; :meth:`finish` checks them and writes
    the metadata. Use through :func:`image_canvas`."""

    def __init__(self, tmp: Path, dest: Path):
        self._tmp, self._dest = tmp, dest
        self.pixels: np.ndarray | None = None
        self.finished = False

    def allocate(self, shape: tuple[int, int, int]) -> np.ndarray:
        self.pixels = tifffile.memmap(self._tmp, shape=tuple(shape), dtype=np.float32,
                                      photometric="minisblack", metadata=None, description="{}",
                                      software=f"plenocli {__version__}")
        # the disk space taken now: a full disk is an error here, not a crash (SIGBUS) while the
        # map is written
        with open(self._tmp, "r+b") as fh:
            try:
                os.posix_fallocate(fh.fileno(), 0, os.fstat(fh.fileno()).st_size)
            except OSError as err:  # a file system that cannot reserve space maps it all the same
                if err.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                    raise
        return self.pixels

    def finish(self, meta: dict) -> None:
        if self.pixels is None:
            raise RuntimeError("finish() before allocate()")
        check_result(self._dest, self.pixels, meta)
        self.pixels.flush()
        tifffile.tiffcomment(self._tmp, describe(meta))
        self.finished = True


@contextlib.contextmanager
def image_canvas(path: str | os.PathLike, *, protect: tuple = ()) -> Iterator[ImageCanvas]:
    """An :class:`ImageCanvas` for ``path``: the file lands (see :mod:`plenocli.io.atomic`) when
    the block ends after :meth:`ImageCanvas.finish`, and not at all if the block fails."""
    with atomic_path(path, protect=protect) as tmp:
        canvas = ImageCanvas(tmp, Path(path))
        yield canvas
        if not canvas.finished:
            raise RuntimeError(f"{path}: the image was not finished")
