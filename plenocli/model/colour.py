"""Colour facts every layer uses: camera RGB -> XYZ -> output RGB spaces (all D65), and
white-balance gains (camera R, G, B multipliers, green = 1).

A raw gives ``xyz_to_camera`` (LibRaw's ``rgb_xyz_matrix``, DNG ``ColorMatrix``): camera RGB of
an XYZ colour. As in dcraw and LibRaw, the camera -> sRGB matrix is the inverse of
``xyz_to_camera @ srgb_to_xyz`` with its rows first normalised to sum 1, so that a white-balanced
neutral stays neutral. Output spaces are linear sRGB / Display P3 / Rec.2020 with their
published primaries (colour-science).
"""

from __future__ import annotations

import warnings

import numpy as np

from plenocli.errors import numbers

OUTPUT_SPACES = {"srgb": "sRGB", "display-p3": "Display P3", "rec2020-linear": "ITU-R BT.2020"}
# Demosaicing methods (plenocli.colour.demosaic; compared in docs/colour.md).
METHODS = ("rcd", "menon2007", "opencv-ea", "opencv-vng", "malvar2004", "bilinear")
DEFAULT_METHOD = "rcd"  # best PSNR and dE2000 on natural photographs (docs/colour.md)
# White-balance gains within this ratio of each other: beyond any light source (a typo, or a
# header that lies), and float overflow further on. --wb and a file's as-shot gains alike.
MAX_GAIN_RATIO = 100.0
CONDITION_LIMIT = 1e6  # beyond this a matrix inverse amplifies rounding into visible colour


def rgb_to_xyz(space: str) -> np.ndarray:
    """The 3 x 3 linear RGB -> XYZ (D65) matrix of an output space (a key of OUTPUT_SPACES)."""
    if space not in OUTPUT_SPACES:
        raise ValueError(f"colour space {space!r} unknown; choose one of "
                         f"{', '.join(OUTPUT_SPACES)}")
    with warnings.catch_warnings():  # colour-science warns about optional plotting packages
        warnings.simplefilter("ignore")
        import colour

        return np.asarray(colour.RGB_COLOURSPACES[OUTPUT_SPACES[space]].matrix_RGB_to_XYZ,
                          np.float64)


def check_invertible(matrix, name: str) -> np.ndarray:
    """``matrix`` as a 3 x 3 float64 array; ValueError if it is not finite and invertible."""
    m = np.asarray(matrix, np.float64)
    if m.shape == (4, 3):  # LibRaw: rows R, G, B, G2
        m = m[:3]
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError(f"{name} must be a finite 3 x 3 matrix, got {np.asarray(matrix).tolist()}")
    if not np.any(m):
        raise ValueError(f"{name} is all zeros (the raw has no colour matrix)")
    if np.linalg.cond(m) > CONDITION_LIMIT:
        raise ValueError(f"{name} {m.round(6).tolist()} is not invertible (condition number "
                         f"{np.linalg.cond(m):.3g}); give a valid matrix or use --matrix none")
    return m


def camera_to_srgb(xyz_to_camera) -> np.ndarray:
    """The camera (white-balanced) -> linear sRGB matrix of dcraw/LibRaw."""
    cam_xyz = check_invertible(xyz_to_camera, "the camera colour matrix (XYZ -> camera)")
    cam_rgb = cam_xyz @ rgb_to_xyz("srgb")
    sums = cam_rgb.sum(axis=1, keepdims=True)
    if np.any(np.abs(sums) < 1e-9):
        raise ValueError("the camera colour matrix maps white to black in some channel; "
                         "it is not a colour matrix")
    return check_invertible(np.linalg.inv(cam_rgb / sums),
                            "the camera -> sRGB matrix")


def srgb_to_space(space: str) -> np.ndarray:
    """Linear sRGB -> linear ``space`` (both D65, no adaptation needed)."""
    return np.linalg.inv(rgb_to_xyz(space)) @ rgb_to_xyz("srgb")


def normalised_gains(gains) -> np.ndarray:
    """Gains (3,) as float64 with green = 1; ValueError unless three finite positive numbers."""
    g = np.asarray(gains, np.float64).ravel()
    if g.size == 4:  # LibRaw's R, G, B, G2
        g = g[:3]
    if g.size != 3 or not np.all(np.isfinite(g)) or np.any(g <= 0):
        raise ValueError(f"white-balance gains must be three finite positive numbers R,G,B, "
                         f"got {numbers(np.ravel(gains))}")
    return g / g[1]


def gains_from_neutral(neutral) -> np.ndarray:
    """Gains from a camera-RGB neutral (DNG AsShotNeutral, or the mean RGB of a grey card)."""
    n = np.asarray(neutral, np.float64).ravel()
    if n.size != 3 or not np.all(np.isfinite(n)) or np.any(n <= 0):
        raise ValueError(f"neutral must be three finite positive camera values, got "
                         f"{numbers(n)}")
    return normalised_gains(1.0 / n)
