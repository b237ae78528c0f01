"""Synthetic focused (type-2) plenoptic captures: a textured plane behind a hex micro-lens array.

The generator is Eq. 3 read backwards. A plane at virtual depth ``g_true`` is imaged by every
micro-lens (i, j) so that sensor pixel (x, y) of micro-image (i, j), centred at c_ij, sees the
plane's texture T at::

    (X, Y) = s * (g_true * ((x, y) - c_ij) + c_ij)

in the coordinates of the refocused image (pixel (R, C) of the refocused image is at (X, Y) =
(C, R)). Refocusing with the same s and g = g_true therefore puts every pixel back where its
texture came from and recovers T up to interpolation; at another g each micro-image lands
magnified by g / g_true about the wrong point and the result blurs.

T is a band-limited random texture: a mean plus K cosines with frequencies up to ``max_freq``
cycles per refocused pixel. A sensor pixel integrates over its 1 x 1 px area, which is a box of
side s * g_true in T's coordinates, so each cosine is sampled exactly with its box-filter factor
sinc(fx s g_true) sinc(fy s g_true): proper antialiasing, no supersampling. The true image
returned is T with the same pixel filter (what an ideal refocus can recover).

Left/right views refocused at g != g_true show T shifted by s (g_true - g) <dx>, <dx> the mean
x offset from the micro-image centre of the pixels in the view: a known disparity.
"""

from __future__ import annotations

import numpy as np

from plenocli.model.lensgrid import LensGrid
from plenocli.synth.capture import SimFile, Simulation

CHANNELS = "RGB"


def random_texture(rng: np.random.Generator, *, components: int = 24, max_freq: float = 0.12,
                   contrast: float = 0.35, mean: float = 0.5, channels: int = 1) -> dict:
    """Parameters of a band-limited texture: per channel, a mean and K cosines.

    Returns a dict with ``mean`` (channels,), ``freq`` (K, 2) cycles/px (fx, fy), ``amp``
    (channels, K) and ``phase`` (channels, K) rad. Amplitudes fall as 1/(1 + f / 0.03) and are
    scaled so that the summed amplitudes equal ``contrast * mean`` (values stay positive).
    """
    radius = max_freq * np.sqrt(rng.uniform(0.02, 1.0, components))
    angle = rng.uniform(0, np.pi, components)
    freq = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)
    amp = rng.uniform(0.5, 1.0, (channels, components)) / (1.0 + radius / 0.03)
    amp *= contrast * mean / amp.sum(axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, (channels, components))
    means = mean * rng.uniform(0.8, 1.2, channels) if channels > 1 else np.array([mean])
    return {"mean": means, "freq": freq, "amp": amp, "phase": phase}


def texture_at(texture: dict, X: np.ndarray, Y: np.ndarray, *, box: float = 0.0,
               channel: int = 0) -> np.ndarray:
    """T at points (X, Y) (refocused-image pixels), averaged over a box of side ``box``."""
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    out = np.full(np.broadcast(X, Y).shape, texture["mean"][channel], float)
    for (fx, fy), a, p in zip(texture["freq"], texture["amp"][channel],
                              texture["phase"][channel], strict=True):
        out += a * np.sinc(fx * box) * np.sinc(fy * box) * np.cos(2 * np.pi * (fx * X + fy * Y) + p)
    return out


def focused_plane(texture: dict, grid: LensGrid, shape: tuple[int, int], *, s: float = 0.2,
                  g_true: float = 4.0, cfa: str | None = None) -> np.ndarray:
    """Sensor image (rows, cols) float64 of the textured plane seen through ``grid``.

    Each pixel takes the texture of its channel (the CFA colour at that pixel, or channel 0)
    at Eq. 3's position, box-filtered over the pixel footprint (side s * g_true).
    """
    rows, cols = shape
    y, x = np.mgrid[0:rows, 0:cols].astype(float)
    i, j = grid.nearest_index(x, y)
    c = grid.lattice_xy(i, j)
    X = s * (g_true * (x - c[..., 0]) + c[..., 0])
    Y = s * (g_true * (y - c[..., 1]) + c[..., 1])
    box = abs(s * g_true)
    if not cfa:
        return texture_at(texture, X, Y, box=box)
    sensor = np.empty(shape)
    for k, colour in enumerate(cfa.upper()):
        r0, c0 = k // 2, k % 2
        sensor[r0::2, c0::2] = texture_at(texture, X[r0::2, c0::2], Y[r0::2, c0::2], box=box,
                                          channel=CHANNELS.index(colour))
    return sensor


def raytrix_scene(*, seed: int = 0, rows: int = 480, cols: int = 640, pitch_px: float = 20.2,
                  angle_rad: float = 0.0, s: float = 0.2, g_true: float = 4.0,
                  cfa: str | None = None, max_freq: float = 0.12) -> tuple[np.ndarray, LensGrid,
                                                                           np.ndarray, dict]:
    """A focused-plenoptic capture of a textured plane, with ground truth.

    Returns
    -------
    sensor : ndarray, float32, (rows, cols)
        The sensor image (Bayer mosaic when ``cfa``), values about 0.3 .. 0.7.
    grid : LensGrid
        The hex lens grid (lattice centres; offset chosen at random inside one cell).
    truth : ndarray, float32, (rows_out, cols_out) or (3, rows_out, cols_out)
        The pixel-filtered texture at the refocused-image pixels (refocus.output_shape).
    info : dict
        JSON-ready parameters: seed, s, g_true, pitch, angle, offset, cfa, texture.
    """
    from plenocli.refocus import check_options, output_shape  # the truth's shape, s and g

    check_options(s=s, g=g_true, view="full", mask_width=0.0, kernel="bilinear", radius=None,
                  cfa=cfa, min_weight=0.0)
    if not (np.isfinite(pitch_px) and pitch_px >= 2):
        raise ValueError(f"pitch_px must be a number >= 2 (paper: 20.2), got {pitch_px}")
    rng = np.random.default_rng(seed)
    offset = tuple(float(v) for v in rng.uniform(0, pitch_px, 2))
    grid = LensGrid(pitch_px=float(pitch_px), angle_rad=float(angle_rad), offset_xy=offset,
                    lattice="hex", image_shape=(rows, cols))
    texture = random_texture(rng, max_freq=max_freq, channels=3 if cfa else 1)
    sensor = focused_plane(texture, grid, (rows, cols), s=s, g_true=g_true, cfa=cfa)
    rows_out, cols_out = output_shape((rows, cols), s)
    Y, X = np.mgrid[0:rows_out, 0:cols_out].astype(float)
    box = abs(s * g_true)
    truth = np.stack([texture_at(texture, X, Y, box=box, channel=k)
                      for k in range(3 if cfa else 1)]).astype(np.float32)
    info = {"seed": seed, "s": s, "g_true": g_true, "pitch_px": pitch_px, "angle_rad": angle_rad,
            "offset_xy": list(offset), "lattice": "hex", "shape": [rows, cols], "cfa": cfa,
            "texture": {k: np.asarray(v).tolist() for k, v in texture.items()},
            "pixel_filter": f"box of side s * g_true = {box:g} refocused pixels"}
    return sensor.astype(np.float32), grid, truth if cfa else truth[0], info


def simulate_raytrix_scene(*, seed: int = 0, rows: int = 480, cols: int = 640,
                           pitch_px: float = 20.2, s: float = 0.2, g_true: float = 4.0,
                           cfa: str | None = None) -> Simulation:
    """A synthetic Raytrix-style capture set.

    Files: ``frames.tif`` (the sensor image, plenocli TIFF, view "raw"), ``grid.yaml`` (the lens
    grid), ``texture.tif`` (true refocused image at g_true, one page per channel); the truth.
    """
    sensor, grid, truth, info = raytrix_scene(seed=seed, rows=rows, cols=cols, pitch_px=pitch_px,
                                              s=s, g_true=g_true, cfa=cfa)
    meta = {"views": ["raw"], "cfa": cfa, "origin": [0, 0], "black_level": [[0.0] * 4],
            "white_level": [1.0], "active_area": [0, 0, rows, cols], "masked_areas": [],
            "camera": "synthetic"}
    names = list(CHANNELS) if cfa else ["T"]
    files = (SimFile("frames.tif", sensor, "image", {"meta": meta}),
             SimFile("grid.yaml", grid, "grid"),
             SimFile("texture.tif", truth, "image", {"meta": {"views": names, "cfa": None}}))
    truth_doc = {"kind": "raytrix-scene", **info,
                 "files": {"frames": "frames.tif", "grid": "grid.yaml",
                           "texture": "texture.tif"}}
    return Simulation(files, truth_doc)
