"""Framing: which part of a frames file a stage works on, and a lens grid in that part's pixels.

Every stage that crops to the active area or takes ``--grid`` (refocus, sai, crosstalk, ...)
goes through here, so that a crop, a CFA phase and a grid line up the same way everywhere.

Metadata facts used (see ``plenocli.io.tiffio``): ``origin`` is the full-sensor (row, col) of
the file's pixel (0, 0); ``active_area`` is (top, left, bottom, right) of the light-sensitive
pixels; ``cfa`` is the pattern at pixel (0, 0); ``views`` names the pages (``R, G, B`` for a
demosaiced colour image).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from plenocli.errors import InputError
from plenocli.io.gridfile import check_lens_rows, read_grid
from plenocli.model.cfa import shift_pattern
from plenocli.model.lensgrid import LensGrid

COLOUR_PAGES = ["R", "G", "B"]
MIN_LENSES_ACROSS = 2  # fewer micro-images across a frame leave nothing to refocus or cut


@dataclass(frozen=True)
class Framing:
    """A rectangle of a frames file: rows ``top:bottom``, columns ``left:right``.

    ``cfa`` is the Bayer pattern at the rectangle's first pixel, ``sensor_origin`` that pixel's
    full-sensor (row, col), ``grid`` the lens grid in the rectangle's pixel coordinates (None
    when no grid was given).
    """

    top: int
    left: int
    bottom: int
    right: int
    cfa: str | None
    sensor_origin: tuple[int, int]
    grid: LensGrid | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.bottom - self.top, self.right - self.left

    def crop(self, pages: np.ndarray) -> np.ndarray:
        """The rectangle of ``pages`` (..., rows, cols): a view, not a copy."""
        return pages[..., self.top:self.bottom, self.left:self.right]


def _origin(meta: dict) -> tuple[int, int]:
    row, col = (int(v) for v in (meta.get("origin") or (0, 0)))
    return row, col


def _area(meta: dict, shape: tuple[int, int]) -> tuple[int, int, int, int]:
    top, left, bottom, right = (int(v) for v in (meta.get("active_area") or (0, 0, *shape)))
    return top, left, bottom, right


def _framing(meta: dict, top: int, left: int, bottom: int, right: int,
             grid: LensGrid | None = None) -> Framing:
    o_row, o_col = _origin(meta)
    return Framing(top, left, bottom, right, shift_pattern(meta.get("cfa"), top, left),
                   (o_row + top, o_col + left), grid)


def active_area(meta: dict, shape: tuple[int, int]) -> Framing:
    """The active (light-sensitive) area of a frames file of page ``shape`` (rows, cols);
    the whole page when the metadata has none."""
    return _framing(meta, *_area(meta, shape))


def load_grid(path: str | os.PathLike, meta: dict, shape: tuple[int, int]) -> LensGrid:
    """Read a lens grid for frames with ``meta`` and page ``shape``.

    A plenocli YAML grid carries its own ``sensor_origin`` and ``image_shape``. A RayCalibData
    XML gives its offset from the image centre: it is placed on the frames' active area (the
    sensor image the camera software calibrated), at that area's sensor origin.
    """
    if Path(path).suffix.lower() != ".xml":
        grid = read_grid(path)
        check_lens_rows(path, grid)
        return grid
    region = active_area(meta, shape)
    return replace(read_grid(path, image_shape=region.shape), sensor_origin=region.sensor_origin)


def grid_framing(meta: dict, shape: tuple[int, int], grid: LensGrid, *,
                 frames_path: str = "frames", grid_path: str = "grid") -> Framing:
    """The part of the frames that ``grid`` describes, with the grid in that part's pixels.

    The grid's image (``image_shape`` at ``sensor_origin``: the white image it was calibrated
    on) must lie inside the frames' active area: masked and over-scan pixels hold no
    micro-images, so a grid that covers them was calibrated on another image. A grid without
    a size covers the frames' active area.
    """
    f_row, f_col = _origin(meta)
    g_row, g_col = (int(v) for v in grid.sensor_origin)
    a_top, a_left, a_bottom, a_right = _area(meta, shape)
    if grid.image_shape is not None:
        g_rows, g_cols = (int(v) for v in grid.image_shape)
        top, left = g_row - f_row, g_col - f_col
        bottom, right = top + g_rows, left + g_cols
        if top < a_top or left < a_left or bottom > a_bottom or right > a_right:
            raise InputError(
                f"{grid_path} was calibrated on a {g_cols} x {g_rows} image at sensor origin "
                f"({g_row}, {g_col}) but the active area of {frames_path} is "
                f"{a_right - a_left} x {a_bottom - a_top} at ({f_row + a_top}, {f_col + a_left}); "
                "use a grid calibrated on a white image of the same camera and crop")
    else:
        top, left, bottom, right = a_top, a_left, a_bottom, a_right
    if min(bottom - top, right - left) < MIN_LENSES_ACROSS * grid.pitch_px:
        raise InputError(f"{grid_path}: lens pitch {grid.pitch_px:g} px, but the "
                         f"{right - left} x {bottom - top} frame area holds fewer than "
                         f"{MIN_LENSES_ACROSS} micro-images across; check the grid's pitch_px "
                         "and that it belongs to these frames")
    dx, dy = f_col + left - g_col, f_row + top - g_row
    return _framing(meta, top, left, bottom, right, grid.shifted(dx, dy) if (dx or dy) else grid)


def frame_grid(grid_path: str | os.PathLike, meta: dict, shape: tuple[int, int], *,
               frames_path: str = "frames") -> Framing:
    """Read the grid at ``grid_path`` and frame it on frames with ``meta`` and page ``shape``:
    the one way every stage that takes ``--grid`` lines a grid up with its frames."""
    grid = load_grid(grid_path, meta, shape)
    return grid_framing(meta, shape, grid, frames_path=str(frames_path),
                        grid_path=str(grid_path))


def sensor_image(pages: np.ndarray, meta: dict) -> np.ndarray:
    """One (rows, cols) float32 sensor image of a frames file: the mean of the colour pages of
    a demosaiced image (R, G, B), else the first page (the first frame of a raw capture)."""
    if list(meta.get("views") or []) == COLOUR_PAGES:
        return pages.astype(np.float32).mean(axis=0)
    return pages[0].astype(np.float32)
