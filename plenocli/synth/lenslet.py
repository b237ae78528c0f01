"""Synthetic lenslet scene frames for calibration: every micro-image shows a textured plane
(Keplerian or Galilean, i.e. inverted) through a vignetting disc with a dark rim, on a hex or
square lattice; optionally a multi-focus array (three lens types of different sharpness on the
cosets of the index-3 sub-lattice) and a *trap*: a scene pattern periodic on a relative of the
lens lattice (2 x or sqrt(3) x the pitch), the kind of periodicity a calibration must not take
for the lattice.

Pure functions: arrays and their ground truth, no files. The content comes from
``plenocli.synth.focused`` (Eq. 3 read backwards); a Galilean camera is the same with a negative
virtual depth.
"""

from __future__ import annotations

import cv2
import numpy as np

from plenocli.model.lensgrid import LATTICES, LensGrid
from plenocli.synth.focused import focused_plane, random_texture

TRAPS = ("double", "sqrt3")


def micro_image_mask(grid: LensGrid, shape: tuple[int, int], *, fill: float = 0.92,
                     edge_px: float = 0.8, falloff: float = 0.5) -> np.ndarray:
    """(rows, cols) float64 >= 0: each micro-image a disc of diameter ``fill`` x pitch,
    darkening towards its rim (``falloff``) with a soft edge of ``edge_px``. With ``fill`` > 1
    the discs overlap and add (as on Galilean cameras whose micro-images spill into their
    neighbours): the overlaps between lenses are then brighter than the lens centres."""
    rows, cols = shape
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    i, j = grid.nearest_index(xx, yy)
    radius = fill * grid.pitch_px / 2
    near = [(0, 0)]
    if fill > 1:
        near += [(1, 0), (-1, 0), (0, 1), (0, -1)] + \
            ([(1, -1), (-1, 1)] if grid.lattice == "hex" else [(1, 1), (-1, -1), (1, -1), (-1, 1)])
    total = np.zeros(shape)
    for di, dj in near:
        c = grid.lattice_xy(i + di, j + dj)
        d = np.hypot(xx - c[..., 0], yy - c[..., 1])
        shade = (1 - falloff * np.clip(d / radius, 0, 1) ** 2) ** 2
        total += shade * 0.5 * (1 - np.tanh((d - radius) / max(edge_px, 1e-3)))
    return total


def trap_pattern(grid: LensGrid, shape: tuple[int, int], kind: str) -> np.ndarray:
    """A sensor-plane pattern periodic on a relative of the lens lattice: "double" (twice the
    pitch) or "sqrt3" (sqrt(3) x the pitch turned 30 deg, hex) / "sqrt2" (square); values in
    [0, 1]. Its first harmonics are what a spectrum of the frame shows strongest."""
    step = LATTICES[grid.lattice]
    if kind == "double":
        pitch, angle = 2 * grid.pitch_px, grid.angle_rad
    elif kind == "sqrt3":
        root, turn = (np.sqrt(3), np.pi / 6) if grid.lattice == "hex" else (np.sqrt(2), np.pi / 4)
        pitch, angle = root * grid.pitch_px, grid.angle_rad + turn
    else:
        raise ValueError(f"kind must be one of {TRAPS}, got {kind!r}")
    relative = LensGrid(pitch, angle, grid.offset_xy, grid.lattice)
    recip = np.linalg.inv(relative.basis()).T
    rows, cols = shape
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    x, y = xx - grid.offset_xy[0], yy - grid.offset_xy[1]
    waves = [recip[0], recip[1]] + ([recip[1] - recip[0]] if step < np.pi / 2 else [])
    total = sum(np.cos(2 * np.pi * (g[0] * x + g[1] * y)) for g in waves)
    return (total + len(waves) / 2) / (1.5 * len(waves))   # about 0 .. 1


def lenslet_scene(shape: tuple[int, int], *, pitch_px: float, angle_rad: float = 0.0,
                  offset_xy: tuple[float, float] | None = None, lattice: str = "hex",
                  galilean: bool = False, multi_focus: bool = False, trap: str | None = None,
                  fill: float = 0.92, falloff: float = 0.5, g_true: float = 3.0,
                  noise: float = 0.01, seed: int = 0
                  ) -> tuple[np.ndarray, dict]:
    """A lenslet frame of a textured plane, with its ground truth.

    Parameters
    ----------
    shape : (rows, cols)
    pitch_px, angle_rad, offset_xy, lattice : the true lattice (offset drawn from ``seed``
        inside one cell of the image centre when None)
    galilean : inverted micro-images (negative virtual depth)
    multi_focus : three lens types whose micro-images are blurred by 0, 1 and 2.5 px (types
        0, 1, 2 on the cosets (i - j) mod 3 = 0, 1, 2)
    trap : None, "double" or "sqrt3": a scene periodic on that relative of the lattice, as
        strong as the texture
    fill, falloff : micro-image diameter (pitches; > 1 overlapping, see
        :func:`micro_image_mask`) and darkening towards the rim
    g_true : virtual depth of the plane (magnitude)
    noise : Gaussian noise, relative to the mean level

    Returns
    -------
    image : (rows, cols) float32, about 0 .. 1
    truth : dict with lattice, pitch_px, angle_rad, offset_xy, galilean, multi_focus, trap and
        ``lens_type_of_coset`` ((0, 1, 2) for a multi-focus array, else None).
    """
    rows, cols = shape
    if not 4 <= pitch_px <= min(rows, cols) / 4:
        raise ValueError(f"pitch_px must be 4 to a quarter of the image side, got {pitch_px}")
    if multi_focus and lattice != "hex":
        raise ValueError("multi_focus needs lattice='hex'")
    rng = np.random.default_rng(seed)
    if offset_xy is None:
        offset_xy = (cols / 2 + rng.uniform(0, pitch_px), rows / 2 + rng.uniform(0, pitch_px))
    grid = LensGrid(float(pitch_px), float(angle_rad), tuple(offset_xy), lattice,
                    image_shape=(rows, cols))
    texture = random_texture(rng, max_freq=0.12, contrast=0.6)
    depth = -g_true if galilean else g_true
    content = focused_plane(texture, grid, (rows, cols), s=1.0 / g_true, g_true=depth)
    if multi_focus:
        yy, xx = np.mgrid[0:rows, 0:cols]
        i, j = grid.nearest_index(xx, yy)
        coset = (i - j) % 3
        blurred = [content] + [cv2.GaussianBlur(content, (0, 0), s) for s in (1.0, 2.5)]
        content = np.choose(coset, blurred)
    if trap is not None:
        content = 0.5 * content + 0.5 * content.mean() * 2 * trap_pattern(grid, shape, trap)
    image = content * micro_image_mask(grid, shape, fill=fill, falloff=falloff)
    image += rng.normal(0.0, noise * float(image.mean()), image.shape)
    truth = {"lattice": lattice, "pitch_px": float(pitch_px), "angle_rad": float(angle_rad),
             "offset_xy": [float(v) for v in offset_xy], "image_shape": [rows, cols],
             "galilean": bool(galilean), "multi_focus": bool(multi_focus), "trap": trap,
             "fill": float(fill), "falloff": float(falloff),
             "g_true": float(g_true), "seed": int(seed),
             "lens_type_of_coset": [0, 1, 2] if multi_focus else None}
    return image.astype(np.float32), truth
