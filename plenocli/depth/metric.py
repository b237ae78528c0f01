"""Metric depth from the virtual depth g with a thin main lens (docs/depth.md).

The main lens (focal length F) images an object at distance z to b = F z / (z - F) behind it.
The micro-lens array sits at b_L behind the main lens, where the focus distance z_f is imaged:
b_L = F z_f / (z_f - F); the sensor is B behind the micro-lenses. A point whose main-lens image
lies a = g B behind the micro-lenses (virtual depth g = a / B; negative: in front of them, the
Galilean case) has b = b_L + g B, hence::

    z = F b / (b - F),   b = b_L + g B

g grows as objects come nearer (b grows). Objects at or beyond infinity (b <= F) have no
distance: NaN.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plenocli.errors import value_words

FIELDS = {"focal_length_mm": "main-lens focal length F (mm)",
          "focus_distance_m": "object distance imaged onto the micro-lens array (m)",
          "mla_sensor_mm": "distance B from the micro-lenses to the sensor (mm)"}
# What a camera can have, wide enough for a phone module (F 2 mm) and a 2 m telescope, a focus
# from 1 cm to 1 km, micro-lenses up to 10 mm from the sensor (plenoptic cameras: 0.1-3 mm); a
# value outside is a value in other units (m for mm) or a typing error.
RANGES = {"focal_length_mm": (1.0, 2000.0), "focus_distance_m": (0.01, 1000.0),
          "mla_sensor_mm": (0.005, 10.0)}


@dataclass(frozen=True)
class Camera:
    focal_length_mm: float
    focus_distance_m: float
    mla_sensor_mm: float

    @property
    def mla_distance_mm(self) -> float:
        """b_L: main lens to micro-lens array (mm)."""
        z_f = 1000.0 * self.focus_distance_m
        return self.focal_length_mm * z_f / (z_f - self.focal_length_mm)


def camera_from_dict(doc) -> Camera:
    """A Camera from a mapping with FIELDS; ValueError naming what is missing or wrong."""
    if not isinstance(doc, dict):
        raise ValueError("a camera file is a YAML mapping with " + ", ".join(FIELDS))
    unknown = sorted(str(k) for k in doc if k not in FIELDS)
    if unknown:
        raise ValueError(f"unknown key(s) {', '.join(unknown)}; a camera file holds "
                         + ", ".join(FIELDS))
    values = {}
    for key, what in FIELDS.items():
        if key not in doc:
            raise ValueError(f"{key} is missing ({what}); a camera file holds "
                             + ", ".join(FIELDS))
        value = doc.get(key)
        lo, hi = RANGES[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not lo <= value <= hi:    # also false for NaN
            raise ValueError(f"{key} must be a number from {lo:g} to {hi:g}: {what}; got "
                             f"{value_words(value)}")
        values[key] = float(value)
    if 1000.0 * values["focus_distance_m"] <= values["focal_length_mm"]:
        raise ValueError("focus_distance_m must be beyond the focal length (an object at or "
                         "inside F is not imaged)")
    return Camera(**values)


def distance_m(g: np.ndarray, camera: Camera) -> np.ndarray:
    """Object distance (m, float32) of virtual depth g; NaN where g is NaN or the image would
    lie at or before the focal plane (at or beyond infinity)."""
    b = camera.mla_distance_mm + np.asarray(g, float) * camera.mla_sensor_mm
    f = camera.focal_length_mm
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(b > f, f * b / (b - f) / 1000.0, np.nan)
    return z.astype(np.float32)
