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
from plenocli.io import samplebits, samplekind
from plenocli.progress import log

MAX_SAID = 4096  # bytes of a codec's messages kept
TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")  # TIFF, BigTIFF
# what a codec says when it decoded only part of the pixels and made up the rest
PIXELS_LOST = ("premature end", "corrupt jpeg data")


def read_plain_image(path: str | os.PathLike, max_pixels: int) -> np.ndarray:
    """The light levels of a plain image (``read_plain_levels``) without their whites."""
    return read_plain_levels(path, max_pixels)[0]


def read_plain_levels(path: str | os.PathLike, max_pixels: int
                      ) -> tuple[np.ndarray, list[tuple[float, str]] | None]:
    """The light levels of a plain image, colour channels in RGB(A) order, a grey image (or a
    palette of grey entries) as one plane, and the white of each of its frames where the file
    declares fewer bits than its word holds (``samplebits``: a PNG's sBIT; None: the word's; a
    BMP of bit masks is refused). InputError in one line for a file that cannot be decoded or whose
    samples are no light levels (``samplekind``)."""
    samplebits.refuse_masked_bmp(path)
    data, grey = _decoded(Path(path), max_pixels)
    return samplebits.png_levels(path, data, grey)


def _decoded(p: Path, max_pixels: int) -> tuple[np.ndarray, bool]:
    """The pixels as OpenCV decodes them (RGB(A) order, a grey as one plane) and whether the
    file declares grey samples."""
    import cv2

    grey = samplekind.declared_kind(p) == "grey"
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
    if grey and data.ndim == 3:
        return data[..., 0], grey  # OpenCV spreads a grey (or a grey table's) over B, G, R
    if data.ndim == 3 and data.shape[2] >= 3:
        data = np.concatenate([data[..., 2::-1], data[..., 3:]], axis=2)  # BGR(A) -> RGB(A)
    return data, grey


def is_tiff(path: str | os.PathLike) -> bool:
    """A TIFF by its first bytes, whatever its name: a TIFF goes to the TIFF reader and its
    rules (OpenCV's libtiff would read a palette or MinIsWhite page as colours or inverted)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(4) in TIFF_MAGIC
    except OSError:
        return False


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
