"""Refractive indices of optical glasses from the Sellmeier equation (Schott catalogue).

    n(lambda)^2 = 1 + sum_k B_k lambda^2 / (lambda^2 - C_k),    lambda in micrometres

The coefficients are Schott's published ones; indices are relative to air, as in the catalogue,
so "air" is exactly 1 and a lens is traced in air of index 1. ``CATALOGUE_ND`` holds the
catalogue's n_d (587.56 nm) so the tests can check that the coefficients reproduce it.

SK16 is Schott's old (lead-containing) glass, replaced by the lead-free N-SK16 with the same
n_d = 1.62041 and nu_d = 60.3; the paper's Table 2 names "SK16". We use the N-SK16 dispersion
for both names; the catalogue n_d is reproduced to 1e-5 (tested).
"""

from __future__ import annotations

import numpy as np

D_LINE_UM = 0.5875618  # helium d line, the wavelength at which catalogues quote n_d
# Wavelengths used for the three colour channels (F, d, C lines would also do).
RGB_WAVELENGTHS_UM = {"R": 0.6563, "G": 0.5876, "B": 0.4861}

# name -> (B1, B2, B3, C1, C2, C3), C in um^2
SELLMEIER = {
    "N-BK7": (1.03961212, 0.231792344, 1.01046945, 0.00600069867, 0.0200179144, 103.560653),
    "N-SK16": (1.34317774, 0.241144399, 0.994317969, 0.00704687339, 0.0229005, 92.7508526),
    "SK16": (1.34317774, 0.241144399, 0.994317969, 0.00704687339, 0.0229005, 92.7508526),
    "F5": (1.3104463, 0.19603426, 0.96612977, 0.00958633048, 0.0457627627, 115.011883),
    "N-SF11": (1.73759695, 0.313747346, 1.89878101, 0.013188707, 0.0623068142, 155.23629),
}
CATALOGUE_ND = {"N-BK7": 1.5168, "N-SK16": 1.62041, "SK16": 1.62041, "F5": 1.60342,
                "N-SF11": 1.78472, "AIR": 1.0}


def glass_names() -> list[str]:
    """Names :func:`refractive_index` knows (case-insensitive), plus "air"."""
    return [*SELLMEIER, "air"]


def refractive_index(glass: str | float, wavelength_um: float | np.ndarray = D_LINE_UM
                     ) -> float | np.ndarray:
    """Refractive index of ``glass`` at ``wavelength_um`` (micrometres), relative to air.

    ``glass`` is a catalogue name ("N-BK7", "SK16", "air", ...) or a number (a constant index,
    e.g. an ideal prism material of n = 1.74). Vectorised over ``wavelength_um``.
    """
    if isinstance(glass, (int, float, np.floating)) and not isinstance(glass, bool):
        if glass < 1.0:
            raise ValueError(f"glass index {glass} is below 1; give an index >= 1 or a name")
        return float(glass) if np.ndim(wavelength_um) == 0 else np.full(
            np.shape(wavelength_um), float(glass))
    name = str(glass).strip().upper()
    lam = np.asarray(wavelength_um, dtype=np.float64)
    if np.any(lam <= 0.2) or np.any(lam > 5.0):
        raise ValueError(f"wavelength_um {wavelength_um} outside 0.2 .. 5 um; give micrometres")
    if name == "AIR":
        n = np.ones_like(lam)
    else:
        key = next((k for k in SELLMEIER if k.upper() == name), None)
        if key is None:
            raise ValueError(f"unknown glass {glass!r}; known: {', '.join(glass_names())} "
                             "or a number (constant index)")
        b1, b2, b3, c1, c2, c3 = SELLMEIER[key]
        lam2 = lam * lam
        n = np.sqrt(1.0 + b1 * lam2 / (lam2 - c1) + b2 * lam2 / (lam2 - c2)
                    + b3 * lam2 / (lam2 - c3))
    return float(n) if n.ndim == 0 else n
