"""Lens prescriptions and exact sequential ray tracing through conic surfaces.

Coordinates: millimetres, z along the optical axis, light travels towards +z, the first surface's
vertex is at z = 0. A surface is a conic of revolution with the standard sag (Zemax, ISO 10110)

    z(r) = c r^2 / (1 + sqrt(1 - (1 + K) c^2 r^2)),    c = 1 / R,

(K = 0 sphere, -1 < K < 0 prolate ellipsoid, K = -1 paraboloid, K < -1 hyperboloid, K > 0
oblate ellipsoid). The paper's Eq. 2 prints (1 - K) and drops the "1 -" under the root; see
docs/optics.md for why the standard reading is the one that fits its Table 2.

Rays meet a conic in closed form (a quadratic in the ray parameter, the root on the sheet through
the vertex), refract with the vector form of Snell's law, and are stopped (``alive`` False) when
they miss a surface, fall outside its clear aperture, or are totally internally reflected.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from plenocli.optics.glass import D_LINE_UM, refractive_index


@dataclass(frozen=True)
class Surface:
    """One interface: the medium after it is ``glass``; ``thickness_mm`` to the next surface.

    ``radius_mm`` is signed (positive: centre of curvature on the +z side); ``math.inf`` is flat.
    ``diameter_mm`` is the clear aperture. A ``stop`` surface is the aperture stop (flat unless a
    radius is given; its diameter is the stop diameter).
    """

    radius_mm: float = math.inf
    thickness_mm: float = 0.0
    glass: str | float = "air"
    diameter_mm: float = math.inf
    conic: float = 0.0
    stop: bool = False

    @property
    def curvature(self) -> float:
        """c = 1 / R (1/mm); 0 for a flat surface."""
        return 0.0 if math.isinf(self.radius_mm) else 1.0 / self.radius_mm

    def sag(self, r_mm: np.ndarray) -> np.ndarray:
        """Sag z(r) (mm) at radial distance ``r_mm``; NaN where the conic does not reach."""
        c, k = self.curvature, self.conic
        r2 = np.asarray(r_mm, dtype=np.float64) ** 2
        root = 1.0 - (1.0 + k) * c * c * r2
        with np.errstate(invalid="ignore"):
            return np.where(root >= 0, c * r2 / (1.0 + np.sqrt(np.maximum(root, 0.0))), np.nan)


# Refractive indices of real media at optical wavelengths: vacuum/air to germanium (~4 in the IR).
MIN_INDEX, MAX_INDEX = 1.0, 4.0


def _check_surface(k: int, s: Surface) -> None:
    """Refuse values no ray can be traced through (NaN anywhere, a zero radius, a negative or
    infinite thickness, an index outside real media): the lens would give numbers, all wrong."""
    if not (math.isfinite(s.thickness_mm) and s.thickness_mm >= 0):
        raise ValueError(f"surface {k}: thickness_mm {s.thickness_mm} must be a finite number "
                         ">= 0 (surfaces are listed in the order light meets them)")
    for name in ("radius_mm", "diameter_mm", "conic"):
        if math.isnan(getattr(s, name)):
            raise ValueError(f"surface {k}: {name} is NaN; give a number")
    if s.radius_mm == 0:
        raise ValueError(f"surface {k}: radius_mm 0 is no surface; give a signed radius, or inf "
                         "for a flat surface")
    if not math.isfinite(s.conic):
        raise ValueError(f"surface {k}: conic {s.conic} must be finite")
    if not isinstance(s.glass, str) and not MIN_INDEX <= s.glass <= MAX_INDEX:
        raise ValueError(f"surface {k}: refractive index {s.glass} must be in "
                         f"[{MIN_INDEX}, {MAX_INDEX}]")


# Surfaces may touch (a stop on a vertex plane, rims in contact) but not cross. A prescription
# printed to four or five figures fixes a rim's sag only to about 1e-3 of the rim's radius
# (Table 2's radius -2.6425 mm, rounded at 5e-5 mm, moves its sag at 1.69 mm by 1.8 um; its
# surfaces 3 and 4 meet 0.67 um inside that rim), so a crossing is counted beyond that.
CROSSING_TOLERANCE = 1e-3


def _check_no_crossing(surfaces: tuple[Surface, ...], vertex_z: list[float]) -> None:
    """Refuse consecutive surfaces that cross inside their common clear aperture: the gap
    between them would be a medium of negative thickness, which no lens has, and the
    sequential trace would lose or misdirect the rays that pass there."""
    for k in range(1, len(surfaces)):
        a, b = surfaces[k - 1], surfaces[k]
        h = min(a.diameter_mm, b.diameter_mm) / 2
        if not math.isfinite(h):
            continue
        r = np.linspace(0.0, h, 257)
        gap = (vertex_z[k] + b.sag(r)) - (vertex_z[k - 1] + a.sag(r))
        gap[np.isnan(gap)] = np.inf  # beyond where a conic reaches (a rim of its own) no crossing
        worst = int(np.argmin(gap))
        if gap[worst] < -CROSSING_TOLERANCE * h:
            raise ValueError(
                f"surfaces {k} and {k + 1} cross {r[worst]:.4g} mm off axis (the gap between "
                f"them is {gap[worst]:.4g} mm there, {a.thickness_mm:g} mm on axis): no lens "
                "has a medium of negative thickness; give a larger thickness or smaller "
                "diameters")


@dataclass(frozen=True)
class Lens:
    """A sequential lens: surfaces in the order light meets them, then the image plane.

    ``image_distance_mm`` is the distance from the last surface's vertex to the sensor (the last
    surface's own thickness when None).
    """

    surfaces: tuple[Surface, ...]
    name: str = "lens"
    image_distance_mm: float | None = None
    notes: str = ""
    vertex_z_mm: tuple[float, ...] = field(init=False)

    def __post_init__(self):
        if not self.surfaces:
            raise ValueError("a lens needs at least one surface")
        for k, s in enumerate(self.surfaces, 1):  # counted as a prescription lists them
            _check_surface(k, s)
        if self.image_distance_mm is not None and not (math.isfinite(self.image_distance_mm)
                                                       and self.image_distance_mm >= 0):
            raise ValueError(f"image_distance_mm {self.image_distance_mm} must be a finite "
                             "number >= 0")
        z, positions = 0.0, []
        for s in self.surfaces:
            positions.append(z)
            z += s.thickness_mm
        object.__setattr__(self, "vertex_z_mm", tuple(positions))
        for k, s in enumerate(self.surfaces, 1):
            if s.diameter_mm <= 0:
                raise ValueError(f"surface {k}: diameter_mm {s.diameter_mm} must be > 0")
            c, h = s.curvature, 0.5 * s.diameter_mm
            if math.isfinite(h) and 1.0 - (1.0 + s.conic) * c * c * h * h < 0:
                raise ValueError(f"surface {k}: conic {s.conic} with radius {s.radius_mm} mm does "
                                 f"not reach the semi-diameter {h} mm (the sag is undefined)")
        _check_no_crossing(self.surfaces, positions)

    @property
    def image_z_mm(self) -> float:
        """z of the image (sensor) plane."""
        last = self.surfaces[-1]
        dist = last.thickness_mm if self.image_distance_mm is None else self.image_distance_mm
        return self.vertex_z_mm[-1] + dist

    @property
    def stop_index(self) -> int:
        """Index of the aperture stop (the first surface when none is flagged)."""
        return next((k for k, s in enumerate(self.surfaces) if s.stop), 0)

    def indices(self, wavelength_um: float = D_LINE_UM) -> np.ndarray:
        """Refractive index before each surface and after the last: shape (surfaces + 1,)."""
        n = [1.0] + [float(refractive_index(s.glass, wavelength_um)) for s in self.surfaces]
        return np.asarray(n)

    def with_image_distance(self, image_distance_mm: float) -> Lens:
        """The same lens with the sensor ``image_distance_mm`` behind the last vertex."""
        return Lens(self.surfaces, name=self.name, image_distance_mm=image_distance_mm,
                    notes=self.notes)


@dataclass
class RayBundle:
    """Rays after a trace: positions (n, 3) mm, unit directions (n, 3), alive (n,) bool.

    ``hits`` (surfaces, n, 3) and ``normals`` (surfaces, n, 3) are the intersection points and
    unit surface normals, kept when the trace is asked to record them (for checks and pictures).
    """

    position: np.ndarray
    direction: np.ndarray
    alive: np.ndarray
    hits: np.ndarray | None = None
    normals: np.ndarray | None = None
    directions_in: np.ndarray | None = None
    directions_out: np.ndarray | None = None


def intersect_conic(position: np.ndarray, direction: np.ndarray, *, radius_mm: float,
                    conic: float, vertex_z_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form ray-conic intersection on the sheet through the vertex.

    Returns the hit points (n, 3) and a bool mask of rays that meet the surface. The conic is
    c (x^2 + y^2 + (1 + K) z^2) - 2 z = 0 in vertex coordinates.
    """
    c = 0.0 if math.isinf(radius_mm) else 1.0 / radius_mm
    p = position.copy()
    p[:, 2] -= vertex_z_mm
    d = direction
    kk = 1.0 + conic
    a = c * (d[:, 0] ** 2 + d[:, 1] ** 2 + kk * d[:, 2] ** 2)
    b_half = c * (p[:, 0] * d[:, 0] + p[:, 1] * d[:, 1] + kk * p[:, 2] * d[:, 2]) - d[:, 2]
    cc = c * (p[:, 0] ** 2 + p[:, 1] ** 2 + kk * p[:, 2] ** 2) - 2.0 * p[:, 2]
    disc = b_half * b_half - a * cc
    meets = disc >= 0
    root = np.sqrt(np.where(meets, disc, 0.0))
    # Both roots, in the forms that do not cancel: q = -(B' + sign(B') sqrt(disc)),
    # t1 = q / A, t2 = C / q (t = C / (-2 B') when A = 0: a line meeting a paraboloid once).
    q = -(b_half + np.copysign(root, b_half))
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = np.where(a != 0, q / np.where(a != 0, a, 1.0), np.inf)
        t2 = np.where(q != 0, cc / np.where(q != 0, q, 1.0), np.inf)
    r2_sheet = c * c * kk
    best = np.full(len(p), np.inf)
    for t in (t1, t2):
        h = position + np.nan_to_num(t, nan=0.0, posinf=0.0)[:, None] * d
        r2 = h[:, 0] ** 2 + h[:, 1] ** 2
        rad = 1.0 - r2_sheet * r2
        # The hit must lie on the sheet through the vertex (not on the far side of an
        # ellipsoid nor on the other sheet of a hyperboloid), ahead of the ray.
        sag = c * r2 / (1.0 + np.sqrt(np.maximum(rad, 0.0)))
        good = (meets & np.isfinite(t) & (t >= -1e-9) & (rad >= -1e-12)
                & (np.abs(h[:, 2] - vertex_z_mm - sag) <= 1e-7 * (1.0 + np.abs(sag))))
        best = np.where(good & (t < best), t, best)
    ok = np.isfinite(best)
    hit = position + np.where(ok, best, np.nan)[:, None] * d
    return hit, ok


def conic_normal(hit: np.ndarray, *, radius_mm: float, conic: float,
                 vertex_z_mm: float) -> np.ndarray:
    """Unit normals (n, 3) of the conic at ``hit``, pointing towards -z near the vertex."""
    c = 0.0 if math.isinf(radius_mm) else 1.0 / radius_mm
    z = hit[:, 2] - vertex_z_mm
    nrm = np.stack([c * hit[:, 0], c * hit[:, 1], c * (1.0 + conic) * z - 1.0], axis=1)
    return nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def refract(direction: np.ndarray, normal: np.ndarray, n1: float | np.ndarray,
            n2: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vector Snell's law: unit ``direction`` (n, 3) through a surface of unit ``normal``.

    Returns the refracted unit directions and a mask of rays that are not totally internally
    reflected. The normal may point either way.
    """
    mu = np.asarray(n1, dtype=np.float64) / np.asarray(n2, dtype=np.float64)
    cos_i = -np.sum(direction * normal, axis=1)
    flip = cos_i < 0
    nrm = np.where(flip[:, None], -normal, normal)
    cos_i = np.abs(cos_i)
    sin2_t = mu * mu * (1.0 - cos_i * cos_i)
    ok = sin2_t <= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    out = mu * direction + (mu * cos_i - cos_t)[:, None] * nrm
    return out, ok


def trace(lens: Lens, position: np.ndarray, direction: np.ndarray, *,
          wavelength_um: float = D_LINE_UM, to_image: bool = True, record: bool = False,
          stop_mask: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
          clip: bool = True) -> RayBundle:
    """Trace rays from ``position`` (n, 3) mm along unit ``direction`` (n, 3) through ``lens``.

    Parameters
    ----------
    to_image
        Propagate the survivors to the image plane (z = ``lens.image_z_mm``).
    record
        Keep every intersection point, normal and direction (memory: surfaces x n x 3 x 4).
    stop_mask
        ``f(x_mm, y_mm) -> bool`` evaluated on the stop surface: False blocks the ray (a pupil
        mask such as a quarter-pupil or a cross).
    clip
        Apply the clear apertures (False traces the bare surfaces, for checks).
    """
    pos = np.array(position, dtype=np.float64, copy=True).reshape(-1, 3)
    d = np.array(direction, dtype=np.float64, copy=True).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    alive = np.ones(len(pos), dtype=bool)
    n = lens.indices(wavelength_um)
    nsurf = len(lens.surfaces)
    hits = np.full((nsurf, len(pos), 3), np.nan) if record else None
    normals = np.full((nsurf, len(pos), 3), np.nan) if record else None
    d_in = np.full((nsurf, len(pos), 3), np.nan) if record else None
    d_out = np.full((nsurf, len(pos), 3), np.nan) if record else None
    for k, (s, z0) in enumerate(zip(lens.surfaces, lens.vertex_z_mm, strict=True)):
        hit, ok = intersect_conic(pos, d, radius_mm=s.radius_mm, conic=s.conic, vertex_z_mm=z0)
        alive &= ok
        if clip and math.isfinite(s.diameter_mm):
            alive &= hit[:, 0] ** 2 + hit[:, 1] ** 2 <= (0.5 * s.diameter_mm) ** 2
        if s.stop and stop_mask is not None:
            alive &= np.asarray(stop_mask(hit[:, 0], hit[:, 1]), dtype=bool)
        nrm = conic_normal(hit, radius_mm=s.radius_mm, conic=s.conic, vertex_z_mm=z0)
        if n[k] != n[k + 1]:
            new_d, ok = refract(d, nrm, n[k], n[k + 1])
            alive &= ok
        else:
            new_d = d
        if record:
            hits[k], normals[k], d_in[k], d_out[k] = hit, nrm, d, new_d
        pos = np.where(alive[:, None], hit, np.nan)
        d = np.where(alive[:, None], new_d, np.nan)
    if to_image:
        t = (lens.image_z_mm - pos[:, 2]) / d[:, 2]
        pos = pos + t[:, None] * d
    return RayBundle(pos, d, alive, hits, normals, d_in, d_out)
