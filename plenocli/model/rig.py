"""A prism rig: a thin main lens with thin prisms at its stop, one view per pupil part (paper
sections 3, 5.2, 6), checked when made. The ray model that maps its views into one undistorted
frame is :mod:`plenocli.stitch.rig`; the rig file is read by :mod:`plenocli.io.rigfile`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class ViewOptics:
    """One view of the rig: ``pupil`` = (sx, sy) the pupil part it sees (each -1, 0 or +1: the
    half or quarter on that side, 0 = the whole extent on that axis); ``prism`` = (sx, sy) the
    direction the prism over that part deviates towards (its thin edge), or None."""

    pupil: tuple[int, int] = (0, 0)
    prism: tuple[int, int] | None = None


@dataclass(frozen=True)
class PrismRig:
    """Main lens + prisms at its stop. Lengths in mm, angles in degrees.

    ``sensor_mm`` is the width of the sensor area a view images (the view's pixel pitch is
    ``sensor_mm / cols``, so the rig holds for views of any resolution). ``aperture_mm`` sets the
    pupil parts' centroids (parallax for a near object; 0 = rays through the pupil centre).
    ``object_distance_mm`` = inf maps directions (scene at infinity).
    """

    focal_mm: float
    sensor_mm: float
    prism_n: float
    prism_apex_deg: float
    views: tuple[ViewOptics, ...] = field(default_factory=tuple)
    aperture_mm: float = 0.0
    object_distance_mm: float = math.inf

    def __post_init__(self):
        for name in ("focal_mm", "sensor_mm", "prism_n"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"rig {name} must be a positive number, got {value}")
        if not 0 <= self.prism_apex_deg < 90:
            raise ValueError(f"rig prism_apex_deg must be in [0, 90), got {self.prism_apex_deg}")
        if not self.object_distance_mm > self.focal_mm:
            raise ValueError(f"rig object_distance_mm {self.object_distance_mm} must exceed the "
                             f"focal length {self.focal_mm}")
        if self.aperture_mm < 0:
            raise ValueError(f"rig aperture_mm must be >= 0, got {self.aperture_mm}")
        for k, v in enumerate(self.views):
            sides = list(v.pupil) + (list(v.prism) if v.prism is not None else [])
            if len(v.pupil) != 2 or (v.prism is not None and len(v.prism) != 2) \
                    or any(s not in (-1, 0, 1) for s in sides):
                raise ValueError(f"rig view {k}: pupil and prism are [sx, sy] with -1, 0 or 1, "
                                 f"got pupil {v.pupil}, prism {v.prism}")

    def with_apex(self, apex_deg: float) -> PrismRig:
        """The same rig with another prism apex angle (for fitting it to data)."""
        return PrismRig(self.focal_mm, self.sensor_mm, self.prism_n, apex_deg, self.views,
                        self.aperture_mm, self.object_distance_mm)

    def to_dict(self) -> dict:
        return {"focal_mm": self.focal_mm, "sensor_mm": self.sensor_mm,
                "prism_n": self.prism_n, "prism_apex_deg": self.prism_apex_deg,
                "aperture_mm": self.aperture_mm,
                "object_distance_mm": (None if math.isinf(self.object_distance_mm)
                                       else self.object_distance_mm),
                "views": [{"pupil": list(v.pupil),
                           "prism": list(v.prism) if v.prism is not None else None}
                          for v in self.views]}

    @classmethod
    def from_dict(cls, data: dict) -> PrismRig:
        """A rig from its dict (YAML/JSON; see :meth:`to_dict`). Raises ValueError naming the
        missing, unknown or bad key."""
        if not isinstance(data, dict):
            raise ValueError("a rig is a mapping with focal_mm, sensor_mm, prism_n, "
                             "prism_apex_deg and views")
        unknown = sorted(set(map(str, data)) - RIG_KEYS)
        if unknown:
            raise ValueError(f"the rig has an unknown key {unknown[0]!r} (keys: "
                             f"{', '.join(sorted(RIG_KEYS))})")
        try:
            views = tuple(ViewOptics(_sides(v, "pupil", (0, 0)), _sides(v, "prism", None))
                          for v in data["views"])
            dist = data.get("object_distance_mm")
            rig = cls(_number(data, "focal_mm"), _number(data, "sensor_mm"),
                      _number(data, "prism_n"), _number(data, "prism_apex_deg"), views,
                      _number(data, "aperture_mm", 0.0),
                      math.inf if dist is None else _number(data, "object_distance_mm"))
        except KeyError as err:
            raise ValueError(f"the rig has no {err.args[0]!r} key") from err
        except TypeError as err:
            raise ValueError(f"the rig has a malformed entry ({err})") from err
        if rig.prism_n <= 1 or rig.prism_n > 4:
            raise ValueError(f"rig prism_n {rig.prism_n} is not a glass's refractive index "
                             "(1 < n <= 4)")
        if not math.isfinite(rig.aperture_mm) or rig.aperture_mm > 2 * rig.focal_mm:
            raise ValueError(f"rig aperture_mm {rig.aperture_mm} must be finite and at most "
                             f"twice focal_mm (f/0.5)")
        if len(set(rig.views)) != len(rig.views):
            raise ValueError("two rig views have the same pupil part and prism: each view sees "
                             "its own part of the pupil")
        return rig


RIG_KEYS = {"focal_mm", "sensor_mm", "prism_n", "prism_apex_deg", "aperture_mm",
            "object_distance_mm", "views"}


def _number(data: dict, key: str, default: float | None = None) -> float:
    """A finite or infinite real number of the rig (NaN, text and booleans refused)."""
    value = data.get(key, default) if default is not None else data[key]
    if value is None and default is not None:
        value = default
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise ValueError(f"rig {key} must be a number, got {value!r}")
    return float(value)


def _sides(view, key: str, default):
    """A view's [sx, sy] entry: two of -1, 0, 1 (integers), or ``default`` when absent/null."""
    if not isinstance(view, dict):
        raise ValueError(f"a rig view is a mapping with pupil and prism, got {view!r}")
    unknown = set(map(str, view)) - {"pupil", "prism"}
    if unknown:
        raise ValueError(f"a rig view has an unknown key {sorted(unknown)[0]!r} (keys: pupil, "
                         "prism)")
    value = view.get(key)
    if value is None:
        return default
    if not isinstance(value, list | tuple) or len(value) != 2 or any(
            isinstance(s, bool) or not isinstance(s, int) or s not in (-1, 0, 1) for s in value):
        raise ValueError(f"rig view {key} is [sx, sy] with each -1, 0 or 1, got {value!r}")
    return tuple(value)
