"""A result TIFF written band by band while a stage computes it.

A panorama is the largest image plenocli makes (1.4 GB of float32 at the 5D Mark IV's size).
Computed whole and then written, it costs its size in memory and its pixels are touched twice.
Here the stage hands over each band of rows as soon as it is final and the band is written
into the file at its place (one ``pwrite`` per page), so the stage's buffers are reused and the
file's pages are filled by the kernel in bulk: writing through a memory map instead faults
every 4 KiB page, and space reserved ahead (``posix_fallocate``) makes ext4 convert its
extents page by page (7-10 x the time of these writes, measured at 1.4 GB). A full disk is a
failed write (an error), never a signal. The metadata is written once the pixels are done.
The file is the same as :func:`tiffio.write_image` writes (one float32 page per view, the JSON
description on the first page), made atomically beside its destination, and checked as that
function checks a result before it lands (a view with no finite pixel, a pixel +-Inf), from
the bands as they pass.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import tifffile

from plenocli import __version__
from plenocli.io.atomic import atomic_path
from plenocli.io.tiffio import check_summary, describe

# Linux writes at most this many bytes in one call
_WRITE_CHUNK = 1 << 30


class ImageCanvas:
    """A float32 result TIFF of (views, rows, cols) written by rows: :meth:`allocate` makes the
    file and returns the function that writes rows of every page, :meth:`finish` checks what
    was written and writes the metadata. Use through :func:`image_canvas`."""

    def __init__(self, tmp: Path, dest: Path):
        self._tmp, self._dest = tmp, dest
        self.shape: tuple[int, int, int] | None = None
        self._fd: int | None = None
        self._offset = 0
        self._finite: np.ndarray | None = None  # per page: a finite pixel was written
        self._infinite: dict[int, list] = {}  # page: [how many +-Inf, first row, its col]
        self.finished = False

    def allocate(self, shape: tuple[int, int, int]):
        """Make the file for ``shape`` (zero-filled); returns :meth:`write_rows`."""
        pixels = tifffile.memmap(self._tmp, shape=tuple(shape), dtype=np.float32,
                                 photometric="minisblack", metadata=None, description="{}",
                                 software=f"plenocli {__version__}")
        self.shape, self._offset = tuple(shape), int(pixels.offset)
        del pixels  # never touched: only the file's layout is wanted
        self._fd = os.open(self._tmp, os.O_RDWR)
        self._finite = np.zeros(shape[0], bool)
        return self.write_rows

    def write_rows(self, rows: slice, pixels: np.ndarray) -> None:
        """Write ``pixels`` (views, len(rows), cols) at ``rows`` of every page."""
        views, height, width = self.shape
        if pixels.shape != (views, rows.stop - rows.start, width):
            raise ValueError(f"rows {rows.start}:{rows.stop} of a {self.shape} image given "
                             f"{pixels.shape}")
        for k in range(views):
            page = np.ascontiguousarray(pixels[k], np.float32)
            self._note(k, rows.start, page)
            _write_all(self._fd, memoryview(page).cast("B"),
                       self._offset + (k * height + rows.start) * width * 4)

    def _note(self, k: int, first_row: int, page: np.ndarray) -> None:
        """What :func:`check_result` checks, learnt from a band as it passes."""
        if not self._finite[k]:
            self._finite[k] = bool(np.isfinite(page).any())
        # fmax and fmin skip NaN and make no temporary: +-Inf shows in them, or nowhere
        if np.fmax.reduce(page, axis=None) == np.inf or np.fmin.reduce(page, axis=None) == -np.inf:
            where = np.argwhere(np.isinf(page))
            self._infinite.setdefault(k, [0, first_row + int(where[0][0]), int(where[0][1])])
            self._infinite[k][0] += len(where)

    def pixels(self) -> np.ndarray:
        """The pixels written so far, read-only (e.g. for a preview)."""
        return tifffile.memmap(self._tmp, mode="r").reshape(self.shape)

    def finish(self, meta: dict) -> None:
        if self._fd is None:
            raise RuntimeError("finish() before allocate()")
        first = min(self._infinite, default=None)
        check_summary(self._dest, meta, self.shape[0], self._finite,
                      None if first is None else (first, *self._infinite[first]))
        self.close()
        tifffile.tiffcomment(self._tmp, describe(meta))
        self.finished = True

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _write_all(fd: int, data: memoryview, offset: int) -> None:
    while len(data):
        done = os.pwrite(fd, data[:_WRITE_CHUNK], offset)
        data, offset = data[done:], offset + done


@contextlib.contextmanager
def image_canvas(path: str | os.PathLike, *, protect: tuple = ()) -> Iterator[ImageCanvas]:
    """An :class:`ImageCanvas` for ``path``: the file lands (see :mod:`plenocli.io.atomic`) when
    the block ends after :meth:`ImageCanvas.finish`, and not at all if the block fails."""
    with atomic_path(path, protect=protect) as tmp:
        canvas = ImageCanvas(tmp, Path(path))
        try:
            yield canvas
        finally:
            canvas.close()
        if not canvas.finished:
            raise RuntimeError(f"{path}: the image was not finished")
