"""Synthetic scenes with ground-truth depth: lenslet frames of planes at known virtual depth g,
and dual-pixel / quad-pixel views with a known disparity.

Lenslet frames. A scene is a list of textured planes, each g(X, Y) = a + bx X + by Y over a
rectangle of the refocused image (X, Y in refocused pixels at scale ``s``, as in Eq. 3) or
everywhere. Sensor pixel (x, y) of micro-image (i, j), u = (x, y) - c_ij, looks at the point
(X, Y) = s (g u + c_ij) of a plane; with g linear in (X, Y) that is solved in closed form::

    g = (a + s (bx cx + by cy)) / (1 - s (bx ux + by uy))

Where several planes are hit, the largest g hides the others: g grows as an object comes
nearer (the main lens images it farther behind the micro-lenses, docs/depth.md). Each plane
has its own band-limited texture, sampled with the
pixel's box filter (side s g) as in :mod:`plenocli.synth.focused`, then the micro-image
vignetting of :func:`plenocli.synth.lenslet.micro_image_mask` and noise. The truth map holds, at
each refocused pixel, the smallest g of the planes that cover it: no estimator code is involved.

Dual/quad-pixel views. A defocused point is a disc of radius R on the sensor; each half-pixel
sees half of it (quad-pixel: a quarter). A half-disc's centroid lies 4R / (3 pi) from the disc's
centre, so the two views of one point are d = 8R / (3 pi) apart: R = 3 pi |d| / 8. Each cosine
of the texture passes through its view's kernel exactly (the complex gain sum w exp(-2 pi i f.t)
over a fine sampling of the half-disc) and the pixel's box filter; A's kernel lies on the side
of -d, B's on the side of +d, so B's content lies d to the right of A's (quad-pixel: S01 right
of S00 by d, S10 below S00 by d). The blur of each view is the asymmetric half-disc, not a
shifted copy: what a real dual-pixel sensor shows.
"""

from __future__ import annotations

import numpy as np

from plenocli.model.lensgrid import LensGrid
from plenocli.synth.capture import SimFile, Simulation
from plenocli.synth.focused import random_texture, texture_at
from plenocli.synth.lenslet import micro_image_mask

SCENES = ("plane", "steps", "slanted")


def scene_planes(scene: str, out_shape: tuple[int, int], *, g: float = 4.0) -> list[dict]:
    """The planes of a named lenslet scene on a refocused image of ``out_shape`` (rows, cols).

    ``plane``: one fronto-parallel plane at ``g`` (negative: a Galilean camera). ``steps``: a
    background at 2.8 and two nearer boxes at 5.0 and 4.0. ``slanted``: g from 2.5 at the left
    edge to 5.5 at the right.
    """
    rows, cols = out_shape
    if scene == "plane":
        return [{"a": g, "bx": 0.0, "by": 0.0, "region": None}]
    if scene == "steps":
        return [{"a": 2.8, "bx": 0.0, "by": 0.0, "region": None},
                {"a": 5.0, "bx": 0.0, "by": 0.0,
                 "region": [0.12 * cols, 0.15 * rows, 0.45 * cols, 0.85 * rows]},
                {"a": 4.0, "bx": 0.0, "by": 0.0,
                 "region": [0.58 * cols, 0.25 * rows, 0.9 * cols, 0.75 * rows]}]
    if scene == "slanted":
        slope = 3.0 / max(cols - 1, 1)
        return [{"a": 2.5, "bx": slope, "by": 0.0, "region": None}]
    raise ValueError(f"scene must be one of {', '.join(SCENES)}, got {scene!r}")


def _inside(region, X, Y) -> np.ndarray:
    if region is None:
        return np.ones(np.broadcast(X, Y).shape, bool)
    x0, y0, x1, y1 = region
    return (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1)


def truth_depth(planes: list[dict], out_shape: tuple[int, int]) -> np.ndarray:
    """(rows_out, cols_out) float32: at each refocused pixel the largest (nearest) g covering
    it."""
    Y, X = np.mgrid[0:out_shape[0], 0:out_shape[1]].astype(float)
    best = np.full(out_shape, -np.inf)
    for p in planes:
        g = p["a"] + p["bx"] * X + p["by"] * Y
        best = np.where(_inside(p["region"], X, Y) & (g > best), g, best)
    return np.where(np.isfinite(best), best, np.nan).astype(np.float32)


def lenslet_depth_frame(grid: LensGrid, shape: tuple[int, int], planes: list[dict], *,
                        s: float, seed: int = 0, noise: float = 0.005, fill: float = 0.92,
                        falloff: float = 0.5, max_freq: float = 0.12) -> np.ndarray:
    """(rows, cols) float32 sensor image of ``planes`` seen through ``grid`` (Eq. 3 backwards)."""
    rng = np.random.default_rng(seed)
    rows, cols = shape
    yy, xx = np.mgrid[0:rows, 0:cols].astype(float)
    i, j = grid.nearest_index(xx, yy)
    c = grid.lattice_xy(i, j)
    cx, cy = c[..., 0], c[..., 1]
    ux, uy = xx - cx, yy - cy
    del xx, yy, i, j, c
    image = np.full(shape, np.nan)
    seen_g = np.full(shape, -np.inf)
    for p in planes:
        texture = random_texture(rng, max_freq=max_freq, contrast=0.6)
        g = (p["a"] + s * (p["bx"] * cx + p["by"] * cy)) / (1 - s * (p["bx"] * ux + p["by"] * uy))
        X, Y = s * (g * ux + cx), s * (g * uy + cy)
        hit = _inside(p["region"], X, Y) & (np.abs(g) > 1) & (g > seen_g)
        image[hit] = texture_at(texture, X[hit], Y[hit], box=s * np.abs(g[hit]))
        seen_g[hit] = g[hit]
    if np.isnan(image).any():
        raise ValueError("the planes leave sensor pixels that see nothing; add a background")
    image *= micro_image_mask(grid, shape, fill=fill, falloff=falloff)
    image += rng.normal(0.0, noise * float(image.mean()), shape)
    return image.astype(np.float32)


# The simulated camera: a 50 mm main lens focused at 2 m, micro-lenses 0.4 mm from the sensor.
CAMERA = {"focal_length_mm": 50.0, "focus_distance_m": 2.0, "mla_sensor_mm": 0.4}


def virtual_depth(distance_m: float, camera: dict = CAMERA) -> float:
    """g of an object ``distance_m`` away: where the thin main lens images it, measured from
    the micro-lenses (on which it images the focus distance) in units of the MLA-sensor gap."""
    f = camera["focal_length_mm"]
    image = 1.0 / (1.0 / f - 1.0 / (1000.0 * distance_m))
    mla = 1.0 / (1.0 / f - 1.0 / (1000.0 * camera["focus_distance_m"]))
    return (image - mla) / camera["mla_sensor_mm"]


def multi_focus_frame(grid: LensGrid, shape: tuple[int, int], planes: list[dict], *, s: float,
                      focus_g: tuple[float, float, float] = (2.5, 4.0, 5.5),
                      type_of_coset: tuple[int, int, int] = (1, 2, 0), blur_per_g: float = 0.8,
                      seed: int = 0) -> np.ndarray:
    """A multi-focus frame: lens type t (on coset (i - j) mod 3 per ``type_of_coset``) is
    focused at virtual depth ``focus_g[t]``; its micro-images are blurred by a Gaussian of
    sigma = blur_per_g |g - focus_g[t]| px, g the true depth at the lens's centre."""
    import cv2

    from plenocli.refocus import output_shape

    frame = lenslet_depth_frame(grid, shape, planes, s=s, seed=seed)
    truth = truth_depth(planes, output_shape(shape, s))
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    i, j = grid.nearest_index(xx, yy)
    c = grid.lattice_xy(i, j)
    rows = np.clip(np.round(s * c[..., 1]).astype(int), 0, truth.shape[0] - 1)
    cols = np.clip(np.round(s * c[..., 0]).astype(int), 0, truth.shape[1] - 1)
    lens_type = np.asarray(type_of_coset)[(i - j) % 3]
    sigma = blur_per_g * np.abs(truth[rows, cols] - np.asarray(focus_g)[lens_type])
    levels = np.arange(0.0, float(sigma.max()) + 0.25, 0.25)
    stack = [frame] + [cv2.GaussianBlur(frame, (0, 0), v) for v in levels[1:]]
    pick = np.clip(np.round(sigma / 0.25).astype(int), 0, len(levels) - 1)
    return np.choose(pick, stack).astype(np.float32)


def simulate_lenslet_depth(*, seed: int = 0, pixels: str | int | None = None,
                           scene: str = "steps", g: float = 4.0, pitch_px: float = 20.2,
                           s: float = 0.2, noise: float = 0.005,
                           distance_m: float = 0.0) -> Simulation:
    """``plenocli simulate lenslet-depth``: frames.tif, grid.yaml and depth.tif (true g on the
    pixel grid of ``plenocli refocus --s S``), truth.json (with the camera of ``CAMERA``).
    ``distance_m`` > 0 puts the ``plane`` scene at that distance (its g from the camera)."""
    from plenocli.refocus import output_shape

    if distance_m > 0:  # with scene=plane only (synth.params.UNUSED_WHEN)
        if 1000.0 * distance_m <= CAMERA["focal_length_mm"]:
            raise ValueError(f"distance_m = {distance_m} m is inside the main lens's focal "
                             f"length ({CAMERA['focal_length_mm']:g} mm): nothing is imaged")
        g = virtual_depth(distance_m)
        if not 1.0 < abs(g) <= 100.0:
            raise ValueError(f"distance_m = {distance_m} m gives g = {g:.3g}; the simulated "
                             "camera images planes with 1 < |g| <= 100")

    rows, cols = _size(pixels, (480, 640))
    if pitch_px > min(rows, cols) / 4:
        raise ValueError(f"pitch_px = {pitch_px} leaves fewer than 4 micro-images across the "
                         f"{rows} x {cols} sensor; give at most {min(rows, cols) / 4:g}")
    rng = np.random.default_rng(seed)
    grid = LensGrid(pitch_px=float(pitch_px), angle_rad=0.0,
                    offset_xy=tuple(float(v) for v in rng.uniform(0, pitch_px, 2)),
                    lattice="hex", image_shape=(rows, cols))
    out_shape = output_shape((rows, cols), s)
    planes = scene_planes(scene, out_shape, g=g)
    frame = lenslet_depth_frame(grid, (rows, cols), planes, s=s, seed=seed + 1, noise=noise)
    truth = truth_depth(planes, out_shape)
    meta = {"views": ["raw"], "cfa": None, "origin": [0, 0], "black_level": [[0.0] * 4],
            "white_level": [1.0], "active_area": [0, 0, rows, cols], "masked_areas": [],
            "camera": "synthetic"}
    files = (SimFile("frames.tif", frame[None], "image", {"meta": meta}),
             SimFile("grid.yaml", grid, "grid"),
             SimFile("depth.tif", truth[None], "image", {"meta": {"views": ["g"], "cfa": None}}))
    doc = {"kind": "lenslet-depth", "scene": scene, "planes": planes, "s": s, "seed": seed,
           "camera": CAMERA, "distance_m": distance_m or None,
           "pitch_px": pitch_px, "shape": [rows, cols], "noise": noise,
           "files": {"frames": "frames.tif", "grid": "grid.yaml", "depth": "depth.tif"}}
    return Simulation(files, doc)


# --------------------------------------------------------------------------- dual/quad pixel
def _part_kernel(d: float, sx: int, sy: int, step: float = 0.05) -> tuple[np.ndarray, ...]:
    """Sample points (tx, ty) and weights of the part of the defocus disc one view sees.

    The disc has radius R = 3 pi |d| / 8; ``sx`` = -1/+1 keeps the half with tx on that side
    of the centre times sign(d) (0: both halves), ``sy`` likewise for ty (quad-pixel)."""
    radius = 3 * np.pi * abs(d) / 8
    if radius < step:
        return np.zeros(1), np.zeros(1), np.ones(1)
    t = np.arange(-radius + step / 2, radius, step)
    tx, ty = np.meshgrid(t, t)
    keep = tx ** 2 + ty ** 2 <= radius ** 2
    sign = np.sign(d)
    if sx:
        keep &= tx * sx * sign > 0
    if sy:
        keep &= ty * sy * sign > 0
    w = keep.astype(float)
    return tx[keep], ty[keep], w[keep] / w.sum()


def _view(texture: dict, X, Y, d_map: np.ndarray, values: list[float], sx: int, sy: int
          ) -> np.ndarray:
    """One view: each region of constant disparity through its own kernel, cosine by cosine."""
    out = np.zeros(d_map.shape)
    for d in values:
        mask = d_map == d
        tx, ty, w = _part_kernel(d, sx, sy)
        region = np.full(int(mask.sum()), texture["mean"][0])
        for (fx, fy), a, p in zip(texture["freq"], texture["amp"][0], texture["phase"][0],
                                  strict=True):
            gain = np.sum(w * np.exp(-2j * np.pi * (fx * tx + fy * ty))) * np.sinc(fx) * np.sinc(fy)
            region += a * np.abs(gain) * np.cos(2 * np.pi * (fx * X[mask] + fy * Y[mask])
                                                + p + np.angle(gain))
        out[mask] = region
    return out


def disparity_views(shape: tuple[int, int], disparities: list[float], *, quad: bool = False,
                    seed: int = 0, noise: float = 0.002, vignetting: float = 0.25
                    ) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Views (A, B) or (S00, S01, S10, S11) of a texture in vertical bands of constant
    disparity, the view names and the (rows, cols) true disparity. Each view carries its own
    vignetting (A brighter on the left, B on the right, as half-pixels are)."""
    rng = np.random.default_rng(seed)
    rows, cols = shape
    texture = random_texture(rng, components=40, max_freq=0.2, contrast=0.6)
    Y, X = np.mgrid[0:rows, 0:cols].astype(float)
    band = np.minimum((X * len(disparities) / cols).astype(int), len(disparities) - 1)
    d_map = np.asarray(disparities, float)[band]
    parts = ({"S00": (-1, -1), "S01": (1, -1), "S10": (-1, 1), "S11": (1, 1)} if quad
             else {"A": (-1, 0), "B": (1, 0)})
    xn = (X - cols / 2) / cols
    yn = (Y - rows / 2) / rows
    views = []
    for sx, sy in parts.values():
        shade = (1 - 0.3 * (xn ** 2 + yn ** 2)) * (1 - vignetting * sx * xn) \
            * (1 - vignetting * sy * yn)
        view = _view(texture, X, Y, d_map, sorted(set(disparities)), sx, sy) * shade
        views.append(view + rng.normal(0, noise, shape))
    return np.stack(views).astype(np.float32), list(parts), d_map.astype(np.float32)


def simulate_disparity(*, seed: int = 0, pixels: str | int | None = None, quad: bool = False,
                       disparities: tuple[float, ...] = (-2.0, -1.2, -0.5, 0.0, 0.3, 0.9, 1.5,
                                                         2.0),
                       noise: float = 0.002) -> Simulation:
    """``plenocli simulate dualpixel-depth`` / ``quadpixel-depth``: views.tif (A, B or the 2 x 2
    SAIs) and disparity.tif (the true disparity), truth.json."""
    rows, cols = _size(pixels, (256, 512))
    views, names, d_map = disparity_views((rows, cols), list(disparities), quad=quad, seed=seed,
                                          noise=noise)
    meta = {"views": names, "cfa": None, "origin": [0, 0], "active_area": [0, 0, rows, cols],
            "masked_areas": [], "camera": "synthetic"}
    files = (SimFile("views.tif", views, "image", {"meta": meta}),
             SimFile("disparity.tif", d_map[None], "image",
                     {"meta": {"views": ["disparity"], "cfa": None}}))
    doc = {"kind": "quadpixel-depth" if quad else "dualpixel-depth", "seed": seed,
           "disparities": list(disparities), "bands": "vertical, equal width, left to right",
           "sign": "+: the right view's (S01's, S10's) content lies right of (below) A's",
           "shape": [rows, cols], "noise": noise,
           "files": {"views": "views.tif", "disparity": "disparity.tif"}}
    return Simulation(files, doc)


def _size(pixels, default: tuple[int, int]) -> tuple[int, int]:
    if not pixels:
        return default
    text = str(pixels).lower()
    try:
        rows, cols = (int(text),) * 2 if text.isdigit() else (int(v) for v in text.split("x"))
    except ValueError as err:
        raise ValueError(f"pixels {pixels!r}: give ROWSxCOLS or one number") from err
    if min(rows, cols) < 64:
        raise ValueError(f"pixels {pixels!r}: give at least 64 x 64")
    return rows, cols
