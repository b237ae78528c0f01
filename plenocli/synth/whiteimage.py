"""Synthetic white images of a micro-lens array, with the true lattice and lens centres.

Each micro-image is a bright disc (radius ``fill * pitch / 2`` with a soft edge of
``edge_px``) shaded by a cos^4-like falloff towards its rim, centred on its lens centre; the lens
centres are a hexagonal (or square) lattice plus optional Gaussian jitter; where soft edges of
neighbouring micro-images overlap their light adds. The whole frame is
multiplied by a main-lens vignetting (quadratic, off-centre), then photon (Poisson) and read
noise are added and the result is quantised to 12-bit DN in uint16. With ``cfa`` the frame is
a Bayer mosaic (per-colour sensitivity). A few dead and hot pixels can be added.

The truth is exact: each micro-image is point-symmetric about its centre (the neighbours' tails
add on top), sampled at pixel
centres (x = col, y = row).
"""

from __future__ import annotations

import numpy as np

from plenocli.model.lensgrid import LensGrid
from plenocli.synth.capture import SimFile, Simulation

COLOUR_GAIN = {"R": 0.55, "G": 1.0, "B": 0.75}


def white_image(shape: tuple[int, int], *, pitch_px: float, angle_rad: float,
                offset_xy: tuple[float, float], lattice: str = "hex", jitter_px: float = 0.0,
                fill: float = 0.95, edge_px: float = 0.6, falloff: float = 0.5,
                vignetting: float = 0.5, full_well_e: float = 6000.0, read_noise_e: float = 4.0,
                cfa: str | None = None, dead_pixels: int = 0, seed: int = 0
                ) -> tuple[np.ndarray, dict]:
    """Render a white image of a lens array.

    Parameters
    ----------
    shape : (rows, cols)
    pitch_px, angle_rad, offset_xy, lattice : the true lattice (see ``LensGrid``)
    jitter_px : standard deviation of each lens centre around its lattice position (px)
    fill : micro-image diameter / pitch
    edge_px : soft-edge width of a micro-image (px)
    falloff : relative darkening at a micro-image's rim (cos^4-like)
    vignetting : relative darkening at the frame corners (main lens)
    full_well_e : electrons at the brightest pixel (sets the photon noise)
    read_noise_e : read noise (electrons, Gaussian)
    cfa : Bayer pattern at (0, 0) (e.g. "RGGB") or None for mono
    dead_pixels : number of dead (0) and as many hot (clipped) pixels
    seed : random seed

    Returns
    -------
    image : (rows, cols) uint16, 12-bit DN
    truth : dict with the lattice, ``centres_xy`` (K, 2) and ``indices`` (K, 2) of the jittered
        centres (lists), and the rendering parameters.
    """
    rows, cols = shape
    if not 2 <= pitch_px <= min(rows, cols):
        raise ValueError(f"pitch_px must be between 2 and the image size, got {pitch_px}")
    rng = np.random.default_rng(seed)
    grid = LensGrid(pitch_px, angle_rad, tuple(offset_xy), lattice, image_shape=(rows, cols))
    value = _micro_images(grid, (rows, cols), jitter_px=jitter_px, seed=seed,
                          radius=fill * pitch_px / 2, edge_px=edge_px, falloff=falloff)
    value *= _main_lens_shading((rows, cols), vignetting, cfa)
    dn = _to_dn(rng, value, full_well_e=full_well_e, read_noise_e=read_noise_e,
                dead_pixels=dead_pixels)
    idx, _ = grid.lens_centres()
    true_centres = _lens_centre(grid, idx[:, 0], idx[:, 1], jitter_px, seed)
    truth = {
        "lattice": lattice, "pitch_px": float(pitch_px), "angle_rad": float(angle_rad),
        "offset_xy": [float(v) for v in offset_xy], "image_shape": [rows, cols],
        "jitter_px": float(jitter_px), "cfa": cfa, "black_level_dn": 64,
        "indices": idx.tolist(), "centres_xy": true_centres.tolist(), "seed": int(seed),
    }
    return dn.astype(np.uint16), truth


def _lens_centre(grid: LensGrid, i: np.ndarray, j: np.ndarray, jitter_px: float,
                 seed: int) -> np.ndarray:
    """(..., 2) centre of lens (i, j): its lattice place plus a per-lens jitter drawn from the
    index (a counter-based stream, so every pixel that asks for a lens gets the same centre)."""
    base = grid.lattice_xy(i, j)
    if jitter_px <= 0:
        return base
    key = (i.astype(np.int64) * 1_000_003 + j.astype(np.int64)) & 0x7FFFFFFF
    return base + jitter_px * _hash_normal(key, seed)


def _micro_images(grid: LensGrid, shape: tuple[int, int], *, jitter_px: float, seed: int,
                  radius: float, edge_px: float, falloff: float) -> np.ndarray:
    """Relative brightness of the micro-images: soft-edged discs darkening towards their rim."""
    rows, cols = shape
    # the discs reaching a pixel belong to its nearest lattice point or a neighbour (jitter is
    # small, discs are at most one pitch across)
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    i0, j0 = grid.nearest_index(xx, yy)
    value = np.zeros((rows, cols))
    neighbours = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, -1), (-1, 1)]
    if grid.lattice == "square":
        neighbours = [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1),
                      (-1, 1)]
    # light of neighbouring micro-images adds (their soft edges overlap): each micro-image keeps
    # its whole point-symmetric profile, so its true centre is exactly its symmetry centre (a
    # nearest-lens assignment would clip jittered micro-images unevenly)
    for di, dj in neighbours:
        c = _lens_centre(grid, i0 + di, j0 + dj, jitter_px, seed)
        d = np.hypot(xx - c[..., 0], yy - c[..., 1])
        shade = (1 - falloff * np.clip(d / radius, 0, 1) ** 2) ** 2
        value += shade * 0.5 * (1 - np.tanh((d - radius) / max(edge_px, 1e-3)))
    return value


def _main_lens_shading(shape: tuple[int, int], vignetting: float, cfa: str | None) -> np.ndarray:
    """The main lens's vignetting (centred off the frame centre) times the colour filters'
    gains."""
    rows, cols = shape
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    cx, cy = cols / 2 + 0.1 * cols, rows / 2 - 0.07 * rows
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / ((rows / 2) ** 2 + (cols / 2) ** 2)
    shading = 1 - vignetting * r2
    if cfa:
        gains = np.empty((2, 2))
        for k, colour in enumerate(cfa.upper()):
            gains[k // 2, k % 2] = COLOUR_GAIN[colour]
        shading *= np.tile(gains, (rows // 2 + 1, cols // 2 + 1))[:rows, :cols]
    return shading


def _to_dn(rng: np.random.Generator, value: np.ndarray, *, full_well_e: float,
           read_noise_e: float, dead_pixels: int) -> np.ndarray:
    """12-bit DN (black 64) of a relative exposure: photon and read noise, then as many dead
    (0) as hot (4095) pixels."""
    electrons = rng.poisson(value * full_well_e).astype(np.float64)
    electrons += rng.normal(0.0, read_noise_e, size=electrons.shape)
    dn = np.clip(np.rint(electrons * (4095 / (1.1 * full_well_e)) + 64), 0, 4095)
    if dead_pixels:
        pos = rng.integers(0, value.size, size=2 * dead_pixels)
        dn.flat[pos[:dead_pixels]] = 0
        dn.flat[pos[dead_pixels:]] = 4095
    return dn


def _hash_normal(key: np.ndarray, seed: int) -> np.ndarray:
    """Two standard normals per integer key, reproducible (a splitmix-style hash + Box-Muller)."""
    def mix(v):
        v = (v ^ (v >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        v = (v ^ (v >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return v ^ (v >> np.uint64(31))

    with np.errstate(over="ignore"):
        k = key.astype(np.uint64) + np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15)
        a, b = mix(k), mix(k + np.uint64(0x632BE59BD9B4E019))
    u1 = ((a >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0 ** 53
    u2 = ((b >> np.uint64(11)).astype(np.float64) + 0.5) / 2.0 ** 53
    r = np.sqrt(-2 * np.log(u1))
    return np.stack([r * np.cos(2 * np.pi * u2), r * np.sin(2 * np.pi * u2)], axis=-1)


def simulate_hexgrid_white(*, seed: int = 0, size: int = 1024, pitch_px: float = 20.2,
                           angle_deg: float = 7.0, jitter_px: float = 0.05,
                           cfa: str | None = "RGGB", lattice: str = "hex") -> Simulation:
    """``white.tif`` (a Bayer or mono white image, uint16), the truth (lattice and every true
    centre) and, for a hex lattice, ``grid_true.xml`` (the true lattice as RayCalibData). The
    offset is drawn from ``seed``."""
    if not (np.isfinite(pitch_px) and 2 <= pitch_px <= size / 4):
        raise ValueError(f"pitch_px must be a number from 2 to size / 4 = {size / 4:g} (a few "
                         f"lenses across), got {pitch_px}")
    rng = np.random.default_rng(seed)
    offset = (size / 2 + rng.uniform(0, pitch_px), size / 2 + rng.uniform(0, pitch_px))
    image, truth = white_image((size, size), pitch_px=pitch_px, angle_rad=np.radians(angle_deg),
                               offset_xy=offset, lattice=lattice, jitter_px=jitter_px, cfa=cfa,
                               seed=seed)
    files = [SimFile("white.tif", image, "tiff", {"photometric": "minisblack"})]
    if lattice == "hex":
        grid = LensGrid(pitch_px, np.radians(angle_deg), offset, lattice, image_shape=(size, size))
        files.append(SimFile("grid_true.xml", grid, "raytrix-xml"))
    return Simulation(tuple(files), truth)
