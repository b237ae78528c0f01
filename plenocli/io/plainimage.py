"""Plain images (PNG, JPEG, BMP, ...) read through OpenCV.

OpenCV's codecs (libpng, libjpeg) print their own warnings and errors on the process's stderr,
below Python: a damaged PNG gave two or three lines before plenocli's one. They are caught
here: an error becomes part of the one-line refusal, as does a warning that pixels are missing
(libjpeg fills a truncated file grey); another warning (a damaged text or colour-profile chunk:
the pixels are whole) is logged with -v.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from plenocli.errors import InputError
from plenocli.progress import log

MAX_SAID = 4096  # bytes of a codec's messages kept
# what a codec says when it decoded only part of the pixels and made up the rest
PIXELS_LOST = ("premature end", "corrupt jpeg data")


def read_plain_image(path: str | os.PathLike, max_pixels: int) -> np.ndarray:
    """The pixels of a plain image as OpenCV decodes them, colour channels in RGB(A) order;
    InputError in one line for a file it cannot decode."""
    import cv2

    p = Path(path)
    png_colour = _png_colour_type(p)
    if png_colour == PNG_PALETTE:
        raise InputError(f"{p}: a palette (colour-index) PNG: its samples are indices into a "
                         "colour table, not light levels; save the sensor image as grey or RGB")
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    with _codec_messages() as said:
        try:
            data = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        except cv2.error as err:  # OpenCV refuses headers beyond 2^30 pixels before allocating
            if "CV_IO_MAX_IMAGE_PIXELS" in str(err):
                raise InputError(f"{p}: the header claims an image of more than {max_pixels} "
                                 "pixels; the file is damaged or not a sensor image") from err
            data = None
    cut = [line for line in said if any(w in line.lower() for w in PIXELS_LOST)]
    if data is not None and cut:   # libjpeg fills the missing part grey and goes on
        raise InputError(f"{p}: damaged image ({'; '.join(cut)}): part of its pixels is missing; "
                         "use a complete copy of the file")
    if data is None:
        why = f" ({'; '.join(said)})" if said else ""
        raise InputError(f"{p}: unreadable image{why}; the file may be truncated, damaged or "
                         "of another type")
    for line in said:
        log.debug("%s: %s", p, line)
    if png_colour == PNG_GREY_ALPHA and data.ndim == 3:
        return data[..., 0]  # OpenCV spreads the grey over B, G, R (the alpha dropped)
    if data.ndim == 3 and data.shape[2] >= 3:
        data = np.concatenate([data[..., 2::-1], data[..., 3:]], axis=2)  # BGR(A) -> RGB(A)
    return data


PNG_PALETTE, PNG_GREY_ALPHA = 3, 4  # IHDR colour types that OpenCV turns into colour


def _png_colour_type(path: Path) -> int | None:
    """The colour type in a PNG's header (byte 25), None for another file."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(26)
    except OSError:
        return None
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head[25]


@contextlib.contextmanager
def _codec_messages() -> Iterator[list[str]]:
    """Collect what C libraries write on file descriptor 2 inside the block (one entry a
    line); nothing is collected when there is no descriptor 2 to borrow."""
    said: list[str] = []
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:
        yield said
        return
    with tempfile.TemporaryFile() as caught:
        os.dup2(caught.fileno(), 2)
        try:
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            text = caught.read(MAX_SAID).decode("utf-8", errors="replace")
            said.extend(" ".join(line.split()) for line in text.splitlines() if line.strip())
