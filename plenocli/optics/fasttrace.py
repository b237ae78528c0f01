"""Compiled (numba) sequential ray tracer: the same maths as :func:`plenocli.optics.lens.trace`
ray by ray, for the heavy users (cross-talk maps, benchmarks). Tested against the numpy tracer.

Pupil masks are limited to the ones the cross-talk study needs: one open quarter of the stop
(signs of x and y) and an opaque cross of given half-width.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from plenocli.optics.glass import D_LINE_UM
from plenocli.optics.lens import Lens


def surface_table(lens: Lens, wavelength_um: float = D_LINE_UM) -> np.ndarray:
    """(surfaces, 7) float64: curvature, conic, vertex z, semi-diameter, n before, n after,
    stop flag."""
    n = lens.indices(wavelength_um)
    rows = []
    for k, (s, z0) in enumerate(zip(lens.surfaces, lens.vertex_z_mm, strict=True)):
        rows.append([s.curvature, s.conic, z0, 0.5 * s.diameter_mm, n[k], n[k + 1],
                     1.0 if s.stop else 0.0])
    return np.asarray(rows, dtype=np.float64)


@numba.njit(cache=True, fastmath=False, inline="always")
def _trace_ray(i, pos, d, table, image_z, quarter_x, quarter_y, cross_half, out_pos, out_dir,
               alive):
    """Trace ray ``i`` through the surface table into the outputs (a numba kernel: the maths of
    :func:`plenocli.optics.lens.trace` for one ray, documented exception to the length rule).
    Inlined into both kernels (a call per ray cost a third of the throughput)."""
    nsurf = table.shape[0]
    px, py, pz = pos[i, 0], pos[i, 1], pos[i, 2]
    norm = math.sqrt(d[i, 0] ** 2 + d[i, 1] ** 2 + d[i, 2] ** 2)
    dx, dy, dz = d[i, 0] / norm, d[i, 1] / norm, d[i, 2] / norm
    ok = True
    for k in range(nsurf):
        c, kk, z0, semi = table[k, 0], 1.0 + table[k, 1], table[k, 2], table[k, 3]
        n1, n2, stop = table[k, 4], table[k, 5], table[k, 6]
        lz = pz - z0
        a = c * (dx * dx + dy * dy + kk * dz * dz)
        b = c * (px * dx + py * dy + kk * lz * dz) - dz
        cc = c * (px * px + py * py + kk * lz * lz) - 2.0 * lz
        disc = b * b - a * cc
        if disc < 0.0:
            ok = False
            break
        root = math.sqrt(disc)
        q = -(b + math.copysign(root, b))
        best = math.inf
        for which in range(2):
            if which == 0:
                t = q / a if a != 0.0 else math.inf
            else:
                t = cc / q if q != 0.0 else math.inf
            if not (t >= -1e-9) or t == math.inf:
                continue
            hx, hy, hz = px + t * dx, py + t * dy, lz + t * dz
            r2 = hx * hx + hy * hy
            rad = 1.0 - kk * c * c * r2
            if rad < -1e-12:
                continue
            sag = c * r2 / (1.0 + math.sqrt(max(rad, 0.0)))
            if abs(hz - sag) <= 1e-7 * (1.0 + abs(sag)) and t < best:
                best = t
        if best == math.inf:
            ok = False
            break
        px, py, pz = px + best * dx, py + best * dy, pz + best * dz
        if px * px + py * py > semi * semi:
            ok = False
            break
        if stop > 0.0:
            if cross_half > 0.0 and (abs(px) < cross_half or abs(py) < cross_half):
                ok = False
                break
            if quarter_x != 0.0 and (quarter_x * px <= 0.0 or quarter_y * py <= 0.0):
                ok = False
                break
        if n1 != n2:
            nx, ny, nz = c * px, c * py, c * kk * (pz - z0) - 1.0
            nn = math.sqrt(nx * nx + ny * ny + nz * nz)
            nx, ny, nz = nx / nn, ny / nn, nz / nn
            cos_i = -(dx * nx + dy * ny + dz * nz)
            if cos_i < 0.0:
                nx, ny, nz, cos_i = -nx, -ny, -nz, -cos_i
            mu = n1 / n2
            sin2_t = mu * mu * (1.0 - cos_i * cos_i)
            if sin2_t > 1.0:
                ok = False
                break
            f = mu * cos_i - math.sqrt(1.0 - sin2_t)
            dx, dy, dz = mu * dx + f * nx, mu * dy + f * ny, mu * dz + f * nz
    alive[i] = ok
    if ok:
        t = (image_z - pz) / dz
        out_pos[i, 0], out_pos[i, 1], out_pos[i, 2] = px + t * dx, py + t * dy, image_z
        out_dir[i, 0], out_dir[i, 1], out_dir[i, 2] = dx, dy, dz
    else:
        for j in range(3):
            out_pos[i, j] = math.nan
            out_dir[i, j] = math.nan


# Two kernels, two functions. numba's on-disk cache is keyed by the Python function, not by
# its compile options: two ``cache=True`` dispatchers of one function share one cache entry and
# whichever is compiled first is loaded for both (numba issue 6845), so the serial kernel could
# silently run the parallel code or the other way round.
@numba.njit(cache=True, fastmath=False)
def _serial_kernel(pos, d, table, image_z, quarter_x, quarter_y, cross_half, out_pos, out_dir,
                   alive):
    for i in range(pos.shape[0]):
        _trace_ray(i, pos, d, table, image_z, quarter_x, quarter_y, cross_half, out_pos,
                   out_dir, alive)


@numba.njit(cache=True, fastmath=False, parallel=True)
def _parallel_kernel(pos, d, table, image_z, quarter_x, quarter_y, cross_half, out_pos, out_dir,
                     alive):
    for i in numba.prange(pos.shape[0]):
        _trace_ray(i, pos, d, table, image_z, quarter_x, quarter_y, cross_half, out_pos,
                   out_dir, alive)


def trace_fast(lens: Lens, position: np.ndarray, direction: np.ndarray, *,
               wavelength_um: float = D_LINE_UM, quarter: tuple[int, int] | None = None,
               cross_half_width_mm: float = 0.0, parallel: bool = True
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trace rays (n, 3) to the image plane. Returns (position, direction, alive).

    ``quarter`` = (sx, sy) keeps only rays crossing the stop where sign(x) = sx and
    sign(y) = sy; ``cross_half_width_mm`` blocks |x| or |y| below it at the stop.
    """
    pos = np.ascontiguousarray(position, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(direction, dtype=np.float64).reshape(-1, 3)
    out_pos = np.empty_like(pos)
    out_dir = np.empty_like(pos)
    alive = np.empty(len(pos), dtype=np.bool_)
    qx, qy = (float(quarter[0]), float(quarter[1])) if quarter else (0.0, 0.0)
    kernel = _parallel_kernel if parallel else _serial_kernel
    kernel(pos, d, surface_table(lens, wavelength_um), float(lens.image_z_mm), qx, qy,
           float(cross_half_width_mm), out_pos, out_dir, alive)
    return out_pos, out_dir, alive
