"""Natural photographs recorded as a real camera records them, with the scene as ground truth.

A photograph (8-bit sRGB, e.g. scikit-image's bundled pictures) is taken as the scene: its
decoded linear sRGB is the truth. The camera sees it through its own spectral response, modelled
by its DNG ColorMatrix (XYZ -> camera RGB; the Canon EOS 5D Mark IV's from Adobe's profile, the
D65 matrix, by default): camera RGB = ColorMatrix @ sRGB->XYZ @ scene. Its AsShotNeutral is the
camera RGB of the scene's white. The mosaic (RGGB) is exposed so that the brightest camera
channel reaches ``peak`` of the raw range, given shot noise (Poisson, ``electrons_per_dn``) and
read noise, and offset by the black level, as a 14-bit raw.

This keeps what every raw developer meets in real files: unbalanced channels (red and blue far
below green in camera RGB), a non-diagonal camera matrix, noise, and the edges and textures of
natural scenes, which charts of flat patches do not have.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plenocli.colour.demosaic import mosaic
from plenocli.model.colour import rgb_to_xyz
from plenocli.synth.chart import camera_sampled

# Adobe DNG profile ColorMatrix2 (D65) of the Canon EOS 5D Mark IV, XYZ -> camera RGB
# (the table dcraw and LibRaw carry, in units of 1/10000).
CANON_5D4_XYZ_TO_CAMERA = np.array([[6446, -366, -864], [-4436, 12204, 2513],
                                    [-952, 2496, 6348]]) / 10000.0


@dataclass(frozen=True)
class NaturalCapture:
    """A raw mosaic of a photograph and what it must develop to.

    ``raw`` (rows, cols) uint16 with pattern ``cfa``; ``truth`` (rows, cols, 3) float32 scene
    linear sRGB (white = 1); ``dn_per_unit``: raw DN above black of a unit of camera green (the
    developed green of a white scene pixel, as-shot balance, is ``dn_per_unit * neutral[1]``).
    """

    raw: np.ndarray
    truth: np.ndarray
    cfa: str
    black: int
    white: int
    xyz_to_camera: np.ndarray
    as_shot_neutral: np.ndarray
    dn_per_unit: float


def srgb_decode(encoded: np.ndarray) -> np.ndarray:
    """Linear values of sRGB-encoded values in [0, 1] (IEC 61966-2-1)."""
    v = np.asarray(encoded, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def natural_capture(photo: np.ndarray, *, seed: int,
                    xyz_to_camera: np.ndarray = CANON_5D4_XYZ_TO_CAMERA, cfa: str = "RGGB",
                    black: int = 512, white: int = 16383, peak: float = 0.9,
                    electrons_per_dn: float = 2.0, read_noise_dn: float = 3.0,
                    low_pass: bool = True) -> NaturalCapture:
    """The raw a camera with ``xyz_to_camera`` records of ``photo`` (rows, cols, 3) uint8 sRGB.

    Rows and columns are cut to even numbers (whole 2 x 2 CFA cells).
    """
    image = np.asarray(photo)
    if image.ndim != 3 or image.shape[-1] != 3 or image.dtype != np.uint8:
        raise ValueError(f"photo must be (rows, cols, 3) uint8 sRGB, got {image.shape} "
                         f"{image.dtype}")
    if not 0 < peak < 100:  # above 1: overexposed, the brightest parts clip at ``white``
        raise ValueError(f"peak must be positive (1: the brightest pixel at white), got {peak}")
    rows, cols = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
    truth = srgb_decode(image[:rows, :cols] / 255.0)
    if low_pass:  # the camera's optical low-pass filter (most Bayer cameras, the 5D IV too)
        truth = camera_sampled(truth, 1)
    to_camera = np.asarray(xyz_to_camera, np.float64) @ rgb_to_xyz("srgb")
    camera = truth @ to_camera.T
    neutral = to_camera.sum(axis=1)  # camera RGB of sRGB white
    dn_per_unit = peak * (white - black) / float(camera.max())
    signal = np.clip(mosaic(camera, cfa) * dn_per_unit, 0, None)
    rng = np.random.default_rng(seed)
    electrons = rng.poisson(signal * electrons_per_dn)
    noisy = electrons / electrons_per_dn + rng.normal(0.0, read_noise_dn, signal.shape)
    raw = np.clip(np.round(black + noisy), 0, white).astype(np.uint16)
    return NaturalCapture(raw, truth.astype(np.float32), cfa, black, white,
                          np.asarray(xyz_to_camera, np.float64), neutral / neutral.max(),
                          dn_per_unit * float(neutral.max()))
