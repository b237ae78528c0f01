"""One ray model of a thin main lens with thin prisms at its stop (paper sections 3, 4.1, 5.2).

Both the rig undistortion of the stitcher (:mod:`plenocli.stitch.rig`) and the simulator
(:mod:`plenocli.synth.prismcam`) trace rays with the functions here, so a rig fitted to a
simulated capture is tested against the same physics that rendered it.

World coordinates: x right, y down (looking from the sensor through the lens), z from the lens
towards the scene, lengths in mm. A view sees the scene through one part of the pupil (a half or
a quarter disk, or the whole pupil) and, optionally, a prism over that part. The ray from sensor
point s leaves the thin lens at pupil point p towards the conjugate scene point
Q = -s z / D (D the image distance, focused on the plane z), is deviated by the prism (two plane
faces, each leaning by A / 2 towards the prism's thin edge: the symmetric, minimum-deviation
mounting; vector Snell's law) and meets the scene plane z.
"""

from __future__ import annotations

import math

import numpy as np

from plenocli.optics.lens import refract

MAX_INDEX = 4.0  # above any optical glass or crystal in the visible (diamond: 2.42)


def image_distance_mm(focal_mm: float, object_distance_mm: float) -> float:
    """D from the thin-lens equation: the sensor distance that images the plane at
    ``object_distance_mm`` sharply (``focal_mm`` for an object at infinity)."""
    if math.isinf(object_distance_mm):
        return focal_mm
    return 1.0 / (1.0 / focal_mm - 1.0 / object_distance_mm)


def pupil_centroid_mm(aperture_mm: float, part: tuple[int, int]) -> np.ndarray:
    """Centroid (2,) mm of the pupil part ``part`` = (sx, sy), each -1, 0 or +1 (the half or
    quarter on that side; 0 = the whole extent on that axis). A half disk of radius r has its
    centroid 4 r / (3 pi) from the diameter; a quarter disk has it on both axes."""
    c = 4 * (aperture_mm / 2) / (3 * math.pi)
    return np.array([part[0] * c, part[1] * c], np.float64)


def prism_deviation_deg(n: float, apex_deg: float) -> dict:
    """Deviation of a thin prism of index ``n`` and apex angle ``apex_deg``.

    Returns ``thin_deg`` ((n - 1) A, the paper's approximation), ``minimum_deg`` (exact minimum
    deviation 2 asin(n sin(A/2)) - A) and ``normal_incidence_deg`` (exact, light entering the
    first face at normal incidence: asin(n sin A) - A).
    """
    if not (math.isfinite(n) and 1 < n <= MAX_INDEX):
        raise ValueError(f"prism index n {n} must be in (1, {MAX_INDEX:g}] (glass: ~1.5 to 2)")
    if not 0 <= apex_deg < 90:
        raise ValueError(f"apex_deg {apex_deg} must be in [0, 90)")
    a = math.radians(apex_deg)
    out = {"thin_deg": (n - 1.0) * apex_deg}
    s_min = n * math.sin(a / 2)
    if s_min > 1:
        raise ValueError(f"a prism of index {n:g} and apex {apex_deg:g} deg reflects every ray "
                         f"totally (n sin(A/2) = {s_min:.3g} > 1); use a smaller apex angle")
    out["minimum_deg"] = math.degrees(2 * math.asin(s_min) - a) if s_min <= 1 else math.nan
    s_norm = n * math.sin(a)
    out["normal_incidence_deg"] = math.degrees(math.asin(s_norm) - a) if s_norm <= 1 else math.nan
    return out


def apex_for_deviation_deg(n: float, deviation_deg: float) -> float | None:
    """The apex angle whose exact minimum deviation is ``deviation_deg``: from n sin(A/2) =
    sin((A + D)/2), tan(A/2) = sin(D/2) / (n - cos(D/2)). None when no apex the prism model
    takes (below 90 deg, and below 2 asin(1/n), past which every ray is reflected totally)
    deviates that much (:func:`max_minimum_deviation_deg`)."""
    if deviation_deg >= max_minimum_deviation_deg(n):
        return None
    half = math.radians(deviation_deg) / 2
    return math.degrees(2 * math.atan(math.sin(half) / (n - math.cos(half))))


def max_minimum_deviation_deg(n: float) -> float:
    """The largest minimum deviation of a prism of index ``n`` whose apex the model takes:
    the minimum deviation grows with the apex, up to 90 deg or 2 asin(1/n) (total reflection),
    whichever comes first."""
    apex = min(math.pi / 2, 2 * math.asin(1.0 / n))
    return math.degrees(2 * math.asin(min(1.0, n * math.sin(apex / 2))) - apex)


def deviate(direction: np.ndarray, *, n: float, apex_deg: float, towards: tuple[int, int],
            reverse: bool = False) -> np.ndarray:
    """Directions (..., 3) of light (going +z) after a thin prism whose thin edge points
    ``towards`` = (sx, sy) (each -1, 0 or +1; both nonzero: the corner prism of a pyramid,
    deviating about (n - 1) A in x and in y).

    ``reverse`` traces back from the exit direction to the entrance direction (exact: the same
    two refractions in the opposite order). NaN where the prism reflects the ray totally.
    """
    shape = direction.shape
    d = direction.reshape(-1, 3)
    t = math.tan(math.radians(apex_deg) / 2)
    n1 = np.array([towards[0] * t, towards[1] * t, 1.0])
    n2 = np.array([-towards[0] * t, -towards[1] * t, 1.0])
    n1 = np.broadcast_to(n1 / np.linalg.norm(n1), d.shape)
    n2 = np.broadcast_to(n2 / np.linalg.norm(n2), d.shape)
    if reverse:  # light running backwards: enter by the exit face, leave by the entrance face
        inside, ok1 = refract(-d, n2, 1.0, n)
        out, ok2 = refract(inside, n1, n, 1.0)
        out = -out
    else:
        inside, ok1 = refract(d, n1, 1.0, n)
        out, ok2 = refract(inside, n2, n, 1.0)
    out[~(ok1 & ok2)] = np.nan
    return out.reshape(shape)


def scene_hits(sensor_xy: np.ndarray, pupil_xy: np.ndarray, *, image_distance_mm: float,
               object_distance_mm: float, prism: tuple[float, float] | None = None,
               towards: tuple[int, int] | None = None, reverse: bool = False) -> np.ndarray:
    """Where the rays from sensor points through pupil points (and the prism) meet the scene.

    Parameters
    ----------
    sensor_xy, pupil_xy : (..., 2) mm, broadcastable.
    image_distance_mm : D, the sensor's distance behind the lens.
    object_distance_mm : z of the scene plane; ``inf`` for directions.
    prism : (n, apex_deg) of the prism over the pupil part, or None (no deviation).
    towards : the prism's thin-edge direction (sx, sy).
    reverse : deviate backwards (:func:`deviate`): the ray that leaves the prism towards the
        conjugate of ``sensor_xy`` entered it from the returned scene point.

    Returns
    -------
    (..., 2): scene points (mm on the plane z), or for z = inf the direction tangents
    (x / z, y / z). NaN where the prism reflects the ray totally.
    """
    s = np.asarray(sensor_xy, np.float64)
    z, dist = object_distance_mm, image_distance_mm
    if math.isinf(z):
        d = np.concatenate([-s, np.full(s.shape[:-1] + (1,), dist)], axis=-1)
    else:
        q = -s * (z / dist)
        d = np.concatenate([q - pupil_xy, np.full(q.shape[:-1] + (1,), z)], axis=-1)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    if prism is not None and towards is not None and prism[1] > 0:
        d = deviate(d, n=prism[0], apex_deg=prism[1], towards=towards, reverse=reverse)
    if math.isinf(z):
        return d[..., :2] / d[..., 2:3]
    return pupil_xy + d[..., :2] * (z / d[..., 2:3])
