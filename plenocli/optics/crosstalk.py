"""Sub-aperture cross-talk of a quad-pixel (N = 2) plenoptic sensor behind a real lens.

Model (paper section 4.2): a white board at ``object_distance_mm`` is imaged by the real main
lens onto a square micro-lens array (thin lenses of focal ``microlens_focal_um``, pitch
phi = N delta / e with e = 1 + d / D, D the exit-pupil distance, so that micro-images are exactly
N x N pixels); pixels of size ``pixel_um`` sit at d = f behind it. A ray reaching the array at
x with slope t lands on the pixel plane at c + f t (c its micro-lens centre), independent of where
it crossed the micro-lens, so its sub-aperture image (SAI) is fixed by its angle alone.
Three quarter pupils of the stop are masked (optionally plus a cross of width ``mask_width_mm``);
the cross-talk ratio is r = max flux on another SAI / flux on the intended SAI.
"""

from __future__ import annotations

import math

import numpy as np

from plenocli.optics.analysis import image_distance, paraxial, pupil_grid
from plenocli.optics.fasttrace import trace_fast
from plenocli.optics.glass import D_LINE_UM
from plenocli.optics.lens import Lens

QUARTERS = {"++": (1, 1), "+-": (1, -1), "-+": (-1, 1), "--": (-1, -1)}


def stop_mask(*, quarter: str | None = "++", cross_width_mm: float = 0.0):
    """A pupil mask ``f(x_mm, y_mm) -> open`` at the stop: one open quarter (signs of x, y, e.g.
    ``"+-"``; None keeps the whole pupil) and an opaque cross of full width ``cross_width_mm``."""
    if quarter is not None and quarter not in QUARTERS:
        raise ValueError(f"quarter {quarter!r}: use one of {', '.join(QUARTERS)} or None")
    if cross_width_mm < 0:
        raise ValueError(f"cross_width_mm {cross_width_mm} must be >= 0")
    sx, sy = QUARTERS[quarter] if quarter else (0, 0)
    half = 0.5 * cross_width_mm

    def is_open(x, y):
        ok = (np.abs(x) >= half) & (np.abs(y) >= half) if half > 0 else np.ones(np.shape(x), bool)
        if sx:
            ok &= (sx * x > 0) & (sy * y > 0)
        return ok

    return is_open


def sai_flux(lens: Lens, *, sensor_mm: float = 3.6, pixel_um: float = 1.2, n: int = 2,
             microlens_focal_um: float = 4.8, object_distance_mm: float = 2000.0,
             quarter: str | None = "++", cross_width_mm: float = 0.0, fields_across: int = 11,
             pupil_rays_across: int = 96, microlens_pitch_um: float | None = None,
             wavelength_um: float = D_LINE_UM, seed: int = 0) -> dict:
    """Flux (ray counts) on each of the n x n SAIs for a white board seen through a pupil mask.

    Returns ``flux`` (n, n) summed over the field, ``flux_by_field`` (fields, n, n), the field
    points on the sensor (mm), the micro-lens pitch (um) and the exit-pupil distance D (mm).
    The lens is refocused (paraxially) from infinity to ``object_distance_mm``.
    ``microlens_pitch_um`` None matches the pitch to the lens's exit pupil (phi = n delta / e).
    """
    for name, value in (("sensor_mm", sensor_mm), ("pixel_um", pixel_um),
                        ("microlens_focal_um", microlens_focal_um),
                        ("object_distance_mm", object_distance_mm)):
        if not value > 0:
            raise ValueError(f"{name} {value} must be > 0")
    if n < 1 or fields_across < 1 or pupil_rays_across < 2:
        raise ValueError("n, fields_across must be >= 1 and pupil_rays_across >= 2")
    near = image_distance(lens, object_distance_mm=object_distance_mm,
                          wavelength_um=wavelength_um)
    shift = near - image_distance(lens, wavelength_um=wavelength_um)
    if not lens.image_z_mm - lens.vertex_z_mm[-1] + shift >= 0:
        raise ValueError(f"object_distance_mm {object_distance_mm:g}: the lens forms no real "
                         "image of a board this near (it would lie "
                         f"{-(lens.image_z_mm - lens.vertex_z_mm[-1] + shift):.3g} mm before "
                         "the last vertex); put the board farther than the focal length")
    focused = lens.with_image_distance(lens.image_z_mm - lens.vertex_z_mm[-1] + shift)
    par = paraxial(focused, wavelength_um=wavelength_um)
    dist_d = par["exit_pupil"]["distance_to_image_mm"]
    f_mm = microlens_focal_um * 1e-3
    delta = pixel_um * 1e-3
    e = 1.0 + f_mm / dist_d
    # Micro-lens pitch phi (mm): micro-images exactly n pixels wide for this exit pupil, unless
    # the caller imposes one (e.g. Table 1's 2.3981 um, designed for the ideal lens's D).
    pitch = n * delta / e if microlens_pitch_um is None else microlens_pitch_um * 1e-3
    efl = par["efl_mm"]
    # Field points: a grid of board points whose (paraxial) images cover the sensor.
    g = ((np.arange(fields_across) + 0.5) / fields_across - 0.5) * sensor_mm
    hx, hy = np.meshgrid(g, g)
    image_pts = np.stack([hx.ravel(), hy.ravel()], axis=1)
    scale = (object_distance_mm - efl) / efl  # |object height / image height| (thin lens)
    obj = -image_pts * scale
    stop_index = focused.stop_index
    stop_z = focused.vertex_z_mm[stop_index]
    stop_d = focused.surfaces[stop_index].diameter_mm
    # Stratified (jittered) pupil samples, seeded: the same rays with and without a mask.
    pupil = pupil_grid(stop_d, pupil_rays_across, rng=np.random.default_rng(seed))
    nf, npup = len(obj), len(pupil)
    start = np.column_stack([np.repeat(obj, npup, axis=0), np.full(nf * npup, -object_distance_mm)])
    target = np.column_stack([np.tile(pupil, (nf, 1)), np.full(nf * npup, stop_z)])
    # The compiled tracer (same maths as lens.trace, tested equal) applies the pupil mask.
    position, direction, alive = trace_fast(
        focused, start, target - start, wavelength_um=wavelength_um,
        quarter=QUARTERS[quarter] if quarter else None, cross_half_width_mm=cross_width_mm / 2)
    x, y = position[:, 0], position[:, 1]
    tx = direction[:, 0] / direction[:, 2]
    ty = direction[:, 1] / direction[:, 2]
    # Micro-lens centres at (k + 1/2) phi; the ray lands at c + f t on the pixel plane.
    cx = (np.floor(x / pitch) + 0.5) * pitch
    cy = (np.floor(y / pitch) + 0.5) * pitch
    px = cx + f_mm * tx
    py = cy + f_mm * ty
    col = np.floor(np.where(alive, px, 0.0) / delta).astype(np.int64) % n
    row = np.floor(np.where(alive, py, 0.0) / delta).astype(np.int64) % n
    field_id = np.repeat(np.arange(nf), npup)
    by_field = np.zeros((nf, n, n))
    np.add.at(by_field, (field_id[alive], row[alive], col[alive]), 1.0)
    return {"flux": by_field.sum(axis=0), "flux_by_field": by_field,
            "field_points_mm": image_pts, "microlens_pitch_um": pitch * 1e3,
            "exit_pupil_distance_mm": dist_d, "image_distance_mm": focused.image_z_mm
            - focused.vertex_z_mm[-1]}


def crosstalk_ratio(flux: np.ndarray, intended: tuple[int, int]) -> float:
    """r = max flux on another SAI / flux on the ``intended`` one (flux: (n, n))."""
    flux = np.asarray(flux, dtype=np.float64)
    own = flux[intended]
    others = np.delete(flux.ravel(), np.ravel_multi_index(intended, flux.shape))
    return math.inf if own == 0 else float(others.max() / own)


def intended_sai(quarter: str, n: int = 2) -> tuple[int, int]:
    """The SAI (row, col) a quarter pupil maps to with an ideal lens: micro-lenses invert the
    pupil, so the pupil quarter at +x (+y) lands on the low column (row) index."""
    sx, sy = QUARTERS[quarter]
    return (0 if sy > 0 else n - 1, 0 if sx > 0 else n - 1)


def crosstalk_report(lens: Lens, *, cross_width_fraction: float = 1 / 15, quarter: str = "++",
                     **options) -> dict:
    """Cross-talk ratio without and with a cross mask of width ``cross_width_fraction`` of the
    stop diameter. ``options`` go to :func:`sai_flux`. Also the fraction of flux the cross
    removes from the full pupil and the worst field point's ratio."""
    if not (np.isfinite(cross_width_fraction) and 0 <= cross_width_fraction < 1):
        raise ValueError(f"cross_width_fraction {cross_width_fraction} must be in [0, 1)")
    for name in ("sensor_mm", "pixel_um", "object_distance_mm"):
        value = options.get(name)
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} {value} must be a finite number > 0")
    stop_d = lens.surfaces[lens.stop_index].diameter_mm
    intended = intended_sai(quarter)
    out = {"quarter": quarter, "intended_sai": list(intended)}
    for label, width in (("no_mask", 0.0), ("cross_mask", cross_width_fraction * stop_d)):
        res = sai_flux(lens, quarter=quarter, cross_width_mm=width, **options)
        if not res["flux"].sum() > 0:
            raise ValueError(f"cross_width_fraction {cross_width_fraction:g}: a cross that wide "
                             f"leaves no traced ray through the {quarter} quarter of the pupil "
                             "(its open corner vanishes at 1/sqrt(2) = 0.707 of the stop); "
                             "give a narrower cross")
        per_field = [crosstalk_ratio(f, intended) for f in res["flux_by_field"] if f.sum() > 0]
        out[label] = {"cross_width_mm": width, "ratio": crosstalk_ratio(res["flux"], intended),
                      "worst_field_ratio": float(np.max(per_field)),
                      "flux": res["flux"].tolist()}
        out["microlens_pitch_um"] = res["microlens_pitch_um"]
        out["exit_pupil_distance_mm"] = res["exit_pupil_distance_mm"]
    full = sai_flux(lens, quarter=None, **options)["flux"].sum()
    crossed = sai_flux(lens, quarter=None, cross_width_mm=cross_width_fraction * stop_d,
                       **options)["flux"].sum()
    out["cross_mask_flux_loss"] = float(1.0 - crossed / full)
    return out
