"""Lens figures: paraxial (focal length, back focal distance, pupils) and real-ray (field of
view, distortion, spot size), plus prism deviation.

Paraxial figures come from a y-nu trace (exact first-order optics of the surfaces' vertex
curvatures; the conic does not enter). Real-ray figures trace exact rays with
:func:`plenocli.optics.lens.trace` to the image plane.
"""

from __future__ import annotations

import math

import numpy as np

from plenocli.optics.glass import D_LINE_UM
from plenocli.optics.lens import Lens, trace
from plenocli.optics.prism import (
    apex_for_deviation_deg,
    max_minimum_deviation_deg,
    prism_deviation_deg,
)

# A focal length this many times the lens's size (track to the image plane or largest clear
# aperture) is no lens: real objectives have |EFL| within ~0.1-20 x their length, and a single
# weak element focusing on its own image plane stays far below; beyond it the y-nu slope is the
# rounding left of surface powers that cancel (afocal), and every figure would be noise.
MAX_EFL_PER_SIZE = 1e4
# An f-number below 1/2 is a numerical aperture above 1: no lens forms it in air.
MIN_F_NUMBER = 0.5


def lens_size_mm(lens: Lens) -> float:
    """The lens's size (mm): its track to the image plane or its largest clear aperture."""
    diameters = [s.diameter_mm for s in lens.surfaces if math.isfinite(s.diameter_mm)]
    return max([lens.image_z_mm, *diameters])


def _ynu(lens: Lens, y: float, u: float, *, first: int = 0, wavelength_um: float = D_LINE_UM
         ) -> tuple[float, float]:
    """Paraxial trace from surface ``first`` (height ``y`` mm, slope ``u`` in the medium before
    it) to just after the last surface. Returns (y at the last surface, slope after it)."""
    n = lens.indices(wavelength_um)
    surfaces = lens.surfaces
    for k in range(first, len(surfaces)):
        s = surfaces[k]
        u = (n[k] * u - y * (n[k + 1] - n[k]) * s.curvature) / n[k + 1]
        if k + 1 < len(surfaces):
            y = y + s.thickness_mm * u
    return y, u


def _to_stop(lens: Lens, y: float, u: float, wavelength_um: float) -> float:
    """Paraxial height at the stop of a ray entering surface 0 with (y, u)."""
    stop = lens.stop_index
    if stop == 0:
        return y
    n = lens.indices(wavelength_um)
    for k in range(stop):
        s = lens.surfaces[k]
        u = (n[k] * u - y * (n[k + 1] - n[k]) * s.curvature) / n[k + 1]
        y = y + s.thickness_mm * u
    return y


def _check_stop_limits(lens: Lens, pupil_radius_mm: float, wavelength_um: float) -> None:
    """ValueError unless the stop limits the axial beam: the paraxial marginal ray through the
    stop's edge must pass inside every surface's clear aperture (else that surface, not the
    stop, sets the pupil, and f-number and pupils computed from the stop are wrong)."""
    n = lens.indices(wavelength_um)
    y, u = pupil_radius_mm, 0.0
    stop = lens.stop_index
    for k, s in enumerate(lens.surfaces):
        half = 0.5 * s.diameter_mm
        if k != stop and abs(y) > half * (1 + 1e-9):
            raise ValueError(
                f"surface {k + 1} (clear aperture {s.diameter_mm:g} mm) is narrower than the "
                f"axial beam the stop (surface {stop + 1}, {lens.surfaces[stop].diameter_mm:g} "
                f"mm) lets through ({2 * abs(y):.4g} mm there): the stop must limit the pupil; "
                "make it smaller or the surface wider")
        u = (n[k] * u - y * (n[k + 1] - n[k]) * s.curvature) / n[k + 1]
        y = y + s.thickness_mm * u


def paraxial(lens: Lens, *, wavelength_um: float = D_LINE_UM) -> dict:
    """First-order figures of ``lens`` (mm), object at infinity, image space in air.

    Returns ``efl_mm``, ``bfd_mm`` (last vertex to paraxial focus), ``f_number``,
    ``entrance_pupil`` {``z_mm`` from the first vertex, ``diameter_mm``}, ``exit_pupil``
    {``z_mm`` from the first vertex, ``distance_to_image_mm`` (the D of the paper, for the
    configured image plane), ``diameter_mm``}.
    """
    y_last, u_last = _ynu(lens, 1.0, 0.0, wavelength_um=wavelength_um)
    size = lens_size_mm(lens)
    if u_last == 0 or (size > 0 and abs(u_last) * MAX_EFL_PER_SIZE * size < 1.0):
        efl = math.inf if u_last == 0 else -1.0 / u_last
        raise ValueError(f"the lens is afocal: its focal length {efl:.3g} mm is more than "
                         f"{MAX_EFL_PER_SIZE:.0e} times its size ({size:.3g} mm); check the radii")
    efl = -1.0 / u_last
    bfd = -y_last / u_last
    stop = lens.stop_index
    stop_radius = 0.5 * lens.surfaces[stop].diameter_mm
    n = lens.indices(wavelength_um)
    # Entrance pupil: the object-space ray that reaches the stop centre (linear in y0, u0 = 1).
    a = _to_stop(lens, 1.0, 0.0, wavelength_um)  # stop height per unit height of a parallel ray
    b = _to_stop(lens, 0.0, 1.0, wavelength_um)
    y0 = -b / a  # chief ray height at the first vertex for u0 = 1
    enp_z = -y0
    enp_d = 2.0 * stop_radius / abs(a)
    _check_stop_limits(lens, 0.5 * enp_d, wavelength_um)
    # Exit pupil: image of the stop by the surfaces from the stop on (Lagrange invariant for the
    # pupil size).
    y_c, u_c = _ynu(lens, 0.0, 1.0, first=stop, wavelength_um=wavelength_um)
    z_last = lens.vertex_z_mm[-1]
    exp_z = z_last - y_c / u_c
    exp_d = 2.0 * stop_radius * n[stop] * 1.0 / abs(n[-1] * u_c)
    if abs(efl) / enp_d < MIN_F_NUMBER:
        raise ValueError(f"f-number {abs(efl) / enp_d:.3g} is below {MIN_F_NUMBER} (a numerical "
                         "aperture above 1), which no lens reaches in air; check the stop "
                         "diameter and the radii")
    return {
        "efl_mm": efl,
        "bfd_mm": bfd,
        "f_number": efl / enp_d,
        "entrance_pupil": {"z_mm": enp_z, "diameter_mm": enp_d},
        "exit_pupil": {"z_mm": exp_z, "diameter_mm": exp_d,
                       "distance_to_image_mm": lens.image_z_mm - exp_z},
    }


def image_distance(lens: Lens, *, object_distance_mm: float = math.inf,
                   wavelength_um: float = D_LINE_UM) -> float:
    """Paraxial distance (mm) from the last vertex to the image of an axial object point at
    ``object_distance_mm`` in front of the first vertex (infinity: the back focal distance)."""
    if math.isinf(object_distance_mm):
        y, u = _ynu(lens, 1.0, 0.0, wavelength_um=wavelength_um)
    else:
        if object_distance_mm <= 0:
            raise ValueError(f"object_distance_mm {object_distance_mm} must be > 0")
        y, u = _ynu(lens, object_distance_mm, 1.0, wavelength_um=wavelength_um)
    return -y / u


def chief_rays(lens: Lens, field_deg: np.ndarray, *, wavelength_um: float = D_LINE_UM,
               iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Start points and directions of chief rays (through the stop centre) for field angles
    ``field_deg`` (n,) in the y-z plane, object at infinity; aimed by secant iteration."""
    theta = np.radians(np.atleast_1d(np.asarray(field_deg, dtype=np.float64)))
    d = np.stack([0 * theta, np.sin(theta), np.cos(theta)], axis=1)
    z_start = -1.0
    enp_z = paraxial(lens, wavelength_um=wavelength_um)["entrance_pupil"]["z_mm"]
    y_start = (z_start - enp_z) * np.tan(theta)  # paraxial aim at the entrance pupil centre
    stop = lens.stop_index
    probe = Lens(lens.surfaces[: stop + 1], name="to-stop", image_distance_mm=0.0)

    def stop_height(y):
        pos = np.stack([0 * y, y, np.full_like(y, z_start)], axis=1)
        return trace(probe, pos, d, wavelength_um=wavelength_um, to_image=False, clip=False
                     ).position[:, 1]

    h0, y0 = stop_height(y_start), y_start
    y1 = y_start - 1e-3
    for _ in range(iterations):
        h1 = stop_height(y1)
        slope = np.where(np.abs(h1 - h0) > 1e-15, (h1 - h0) / (y1 - y0), 1.0)
        y0, h0, y1 = y1, h1, y1 - h1 / slope
        if np.all(np.abs(h1) < 1e-12):
            break
    pos = np.stack([0 * y1, y1, np.full_like(y1, z_start)], axis=1)
    return pos, d


def real_image_height(lens: Lens, field_deg: np.ndarray, *, wavelength_um: float = D_LINE_UM
                      ) -> np.ndarray:
    """Height (mm) where the chief ray of each field angle meets the image plane."""
    pos, d = chief_rays(lens, field_deg, wavelength_um=wavelength_um)
    return trace(lens, pos, d, wavelength_um=wavelength_um, clip=False).position[:, 1]


def paraxial_image_height(lens: Lens, field_deg: np.ndarray, *,
                          wavelength_um: float = D_LINE_UM) -> np.ndarray:
    """Height (mm) of the paraxial chief ray on the lens's image plane for field angles (deg).

    Equals f tan(theta) when the image plane is at the paraxial focus; it includes the small
    scale change of a defocused image plane otherwise (the reference Zemax uses).
    """
    tan_t = np.tan(np.radians(np.asarray(field_deg, dtype=np.float64)))
    a = _to_stop(lens, 1.0, 0.0, wavelength_um)
    b = _to_stop(lens, 0.0, 1.0, wavelength_um)
    y_last, u_last = _ynu(lens, -b / a, 1.0, wavelength_um=wavelength_um)
    per_unit = y_last + (lens.image_z_mm - lens.vertex_z_mm[-1]) * u_last
    return per_unit * tan_t


def distortion_percent(lens: Lens, field_deg: np.ndarray, *, wavelength_um: float = D_LINE_UM
                       ) -> np.ndarray:
    """Distortion 100 (h_real - h_paraxial) / h_paraxial at each (non-zero) field angle, with
    both chief-ray heights taken on the lens's image plane."""
    field = np.atleast_1d(np.asarray(field_deg, dtype=np.float64))
    if np.any(field == 0):
        raise ValueError("field_deg must be non-zero "
                         "(distortion is a ratio to the paraxial height)")
    ideal = paraxial_image_height(lens, field, wavelength_um=wavelength_um)
    return 100.0 * (real_image_height(lens, field, wavelength_um=wavelength_um) - ideal) / ideal


def half_field_deg(lens: Lens, image_half_height_mm: float, *,
                   wavelength_um: float = D_LINE_UM) -> float:
    """The field angle (deg) whose chief ray lands at ``image_half_height_mm`` (bisection)."""
    if image_half_height_mm <= 0:
        raise ValueError(f"image_half_height_mm {image_half_height_mm} must be > 0")
    lo, hi = 0.0, 89.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        h = abs(real_image_height(lens, np.array([mid]), wavelength_um=wavelength_um)[0])
        if not np.isfinite(h) or h > image_half_height_mm:
            hi = mid
        else:
            lo = mid
    reached = abs(real_image_height(lens, np.array([lo]), wavelength_um=wavelength_um)[0])
    if not (np.isfinite(reached) and reached >= image_half_height_mm * (1 - 1e-3)):
        raise ValueError(f"no chief ray reaches {image_half_height_mm:g} mm off axis (the "
                         f"lens's image circle ends near {reached:.3g} mm); give a smaller "
                         "sensor (--sensor-mm)")
    return 0.5 * (lo + hi)


def pupil_grid(diameter_mm: float, rays_across: int, *,
               rng: np.random.Generator | None = None) -> np.ndarray:
    """Square-grid sample points (n, 2) inside a disc of ``diameter_mm`` (mm).

    With ``rng`` each point is jittered uniformly inside its grid cell (stratified sampling),
    which avoids aliasing with masks aligned to the grid (a cross at the stop).
    """
    if rays_across < 2:
        raise ValueError(f"rays_across {rays_across} must be >= 2")
    r = 0.5 * diameter_mm
    g = (np.arange(rays_across) + 0.5) / rays_across * 2.0 - 1.0
    x, y = np.meshgrid(g * r, g * r)
    if rng is not None:
        cell = 2.0 * r / rays_across
        x = x + (rng.random(x.shape) - 0.5) * cell
        y = y + (rng.random(y.shape) - 0.5) * cell
    keep = x ** 2 + y ** 2 <= r * r
    return np.stack([x[keep], y[keep]], axis=1)


def spot_rms_um(lens: Lens, field_deg: float, *, rays_across: int = 32,
                wavelength_um: float = D_LINE_UM) -> float:
    """RMS spot radius (um) about the centroid at the image plane for a field angle (deg).

    Rays fill the entrance pupil on a square grid (aimed at the paraxial entrance pupil; rays
    the apertures stop are dropped).
    """
    par = paraxial(lens, wavelength_um=wavelength_um)
    grid = pupil_grid(par["entrance_pupil"]["diameter_mm"], rays_across)
    theta = math.radians(field_deg)
    d = np.tile([0.0, math.sin(theta), math.cos(theta)], (len(grid), 1))
    chief_pos, _ = chief_rays(lens, np.array([field_deg]), wavelength_um=wavelength_um)
    z_start = chief_pos[0, 2]
    # Shift the grid along the chief ray: the pupil grid sits on the plane z = z_start.
    pos = np.column_stack([grid[:, 0], grid[:, 1] / math.cos(theta) + chief_pos[0, 1],
                           np.full(len(grid), z_start)])
    out = trace(lens, pos, d, wavelength_um=wavelength_um)
    xy = out.position[out.alive, :2]
    if len(xy) == 0:
        return math.nan
    return float(1e3 * np.sqrt(np.mean(np.sum((xy - xy.mean(axis=0)) ** 2, axis=1))))


def lens_report(lens: Lens, *, sensor_mm: float = 3.6, wavelength_um: float = D_LINE_UM,
                spot_rays_across: int = 32, prism_n: float = 1.74,
                prism_apex_deg: float = 16.7) -> dict:
    """All figures of ``lens`` for a square sensor of side ``sensor_mm``.

    The image plane is the lens's configured one; ``focus`` tells how far it is from the
    paraxial focus for an object at infinity.
    """
    if not (math.isfinite(sensor_mm) and sensor_mm > 0):
        raise ValueError(f"sensor_mm {sensor_mm} must be a finite number > 0")
    par = paraxial(lens, wavelength_um=wavelength_um)
    offset = (lens.image_z_mm - lens.vertex_z_mm[-1]) - par["bfd_mm"]
    if not abs(offset) <= abs(par["efl_mm"]):
        raise ValueError(f"the image plane lies {offset:+.6g} mm from the focus, beyond the "
                         f"focal length ({par['efl_mm']:.6g} mm): the sensor is nowhere near "
                         "focus and every figure (field, distortion, spots) would describe a "
                         "blur; check image_distance_mm")
    # A point on the axis is spread over |offset| / N (the marginal rays' cone): once that is
    # wider than the sensor, no point of the scene is imaged on it at all.
    blur = abs(offset / par["f_number"])
    if blur > sensor_mm:
        raise ValueError(f"the image plane lies {offset:+.6g} mm from the focus: a point on the "
                         f"axis is spread over {blur:.4g} mm there (|offset| / f-number "
                         f"{abs(par['f_number']):.3g}), wider than the {sensor_mm:g} mm sensor, "
                         "so every figure (field, distortion, spots) would describe a blur; "
                         "check image_distance_mm and that every length is in mm")
    half = half_field_deg(lens, sensor_mm / 2, wavelength_um=wavelength_um)
    half_diag = half_field_deg(lens, sensor_mm / math.sqrt(2), wavelength_um=wavelength_um)
    fractions = np.array([0.25, 0.5, 0.7, 0.85, 1.0])
    fields = fractions * half_diag
    dist = distortion_percent(lens, fields, wavelength_um=wavelength_um)
    spots = [spot_rms_um(lens, float(f), rays_across=spot_rays_across,
                         wavelength_um=wavelength_um) for f in [0.0, *fields]]
    dark = [float(f) for f, s in zip([0.0, *fields], spots, strict=True) if not s == s]
    if dark:  # the chief ray alone is no image: the figures there would describe no light
        raise ValueError(f"no ray of the pupil but the chief ray reaches the image {dark[0]:.1f} "
                         f"deg off axis (the sensor's corner is at {half_diag:.1f} deg): the lens "
                         "vignettes it completely; give a smaller sensor (--sensor-mm)")
    ideal_half = math.degrees(math.atan(sensor_mm / 2 / par["efl_mm"]))
    apex = apex_for_deviation_deg(prism_n, ideal_half)
    return {
        "lens": lens.name,
        "wavelength_um": wavelength_um,
        "sensor_mm": sensor_mm,
        **par,
        "image_distance_mm": lens.image_z_mm - lens.vertex_z_mm[-1],
        "focus_offset_mm": offset,
        "field_of_view_deg": {"horizontal": 2 * half, "diagonal": 2 * half_diag,
                              "paraxial_horizontal": 2 * ideal_half},
        "distortion_percent": [{"field_deg": float(f), "percent": float(p)}
                               for f, p in zip(fields, dist, strict=True)],
        "max_abs_distortion_percent": float(np.max(np.abs(dist))),
        "spot_rms_um": [{"field_deg": float(f), "rms_um": s}
                        for f, s in zip([0.0, *fields], spots, strict=True)],
        "prism": {"n": prism_n, "apex_deg": prism_apex_deg,
                  **prism_deviation_deg(prism_n, prism_apex_deg),
                  # None: no prism of this glass deviates light by half the field
                  "apex_for_half_field_deg": apex,
                  "max_minimum_deviation_deg": max_minimum_deviation_deg(prism_n)},
    }
