"""Image-quality figures against a known truth: PSNR and CIE dE2000 (colour-science)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ColourError:
    """How far an RGB image is from its truth."""

    psnr_db: float
    delta_e_mean: float
    delta_e_p95: float


def psnr(image: np.ndarray, truth: np.ndarray, *, peak: float = 1.0) -> float:
    """Peak signal-to-noise ratio (dB) over the finite pixels of ``image``."""
    diff = np.asarray(image, np.float64) - np.asarray(truth, np.float64)
    diff = diff[np.isfinite(diff)]
    if diff.size == 0:
        raise ValueError("image has no finite pixel to compare")
    mse = float(np.mean(diff**2))
    return float("inf") if mse == 0 else 10.0 * np.log10(peak**2 / mse)


def delta_e_2000(rgb: np.ndarray, truth_rgb: np.ndarray) -> np.ndarray:
    """CIE dE2000 between two linear sRGB (D65) images (..., 3), per pixel."""
    with warnings.catch_warnings():  # colour-science warns about optional plotting packages
        warnings.simplefilter("ignore")
        import colour

        def lab(x):
            xyz = colour.RGB_to_XYZ(np.asarray(x, np.float64), "sRGB",
                                    apply_cctf_decoding=False)
            return colour.XYZ_to_Lab(xyz, colour.CCS_ILLUMINANTS[
                "CIE 1931 2 Degree Standard Observer"]["D65"])

        return np.asarray(colour.delta_E(lab(rgb), lab(truth_rgb), method="CIE 2000"))


def colour_error(rgb: np.ndarray, truth_rgb: np.ndarray, *, border: int = 8) -> ColourError:
    """PSNR (peak 1) and dE2000 mean / 95th percentile of linear sRGB ``rgb`` against its truth,
    ``border`` pixels from each edge left out; NaN pixels are left out too."""
    a = np.asarray(rgb)[border:-border or None, border:-border or None]
    b = np.asarray(truth_rgb)[border:-border or None, border:-border or None]
    finite = np.isfinite(a).all(axis=-1)
    de = delta_e_2000(a[finite], b[finite])
    return ColourError(psnr(a[finite], b[finite]), float(de.mean()),
                       float(np.percentile(de, 95)))
