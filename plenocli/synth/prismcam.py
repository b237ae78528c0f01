"""Synthetic captures of the paper's wide-field designs, rendered from a test chart.

Ideal optics (paper section 4.1): a thin main lens focused on a chart at ``object_distance_mm``,
ideal micro-lenses, and prisms at the aperture stop. A view (sub-aperture image) sees the chart
through one part of the pupil; its ray from a sensor point s leaves the thin lens at pupil point
p towards the conjugate chart point Q = -s z / D (D the image distance), is deviated exactly by
that part's prism (two plane faces, vector Snell's law) and meets the chart plane. Views are then
multiplexed on the sensor the way each sensor does it:

- ``quadpixel``: N = 2 micro-images of 2 x 2 pixels: L(2k + i, 2l + j) = S_ij(k, l) (paper Eq. 1).
  Micro-lenses invert the pupil, so SAI (i, j) sees the pupil quarter on the -y side for i = 1
  and on the -x side for j = 1 (x right, y down, looking from the sensor through the lens).
- ``dualpixel``: each pixel split in a left (A) and right (B) photodiode; A sees the +x pupil
  half. Frames S = A + B and A, as a Canon DPRAW.
- ``raytrix``: a focused (type-2, Galilean) camera with a hexagonal micro-lens array: pixel x
  under the micro-lens of centre c sees the main-lens image point c + g (x - c); pixels left of
  c (x - c < 0) see the +x pupil half.

World coordinates: x right, y down, z from the lens towards the chart (mm). Ground truth is a
plain dict (``truth.json``): the geometry, and for every view the chart area it covers (mm and
field angles in degrees, measured by tracing the view's corner rays).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from plenocli.optics import prism as optics_prism
from plenocli.synth.chart import test_chart_u8

FULL_SCALE_DN = 50000  # 16-bit value of a white chart seen through the whole pupil


@dataclass(frozen=True)
class Camera:
    """Ideal thin-lens camera (paper Table 1 by default). Lengths in mm."""

    focal_mm: float = 6.16
    aperture_mm: float = 3.09
    sensor_mm: float = 3.6
    object_distance_mm: float = 2000.0
    prism_n: float = 1.74
    prism_apex_deg: float = 16.7

    @property
    def image_distance_mm(self) -> float:
        """D from the thin-lens equation (sharp image of the chart)."""
        return optics_prism.image_distance_mm(self.focal_mm, self.object_distance_mm)

    @property
    def half_field_deg(self) -> float:
        """Half field theta = atan(T / 2F) of the main lens alone."""
        return math.degrees(math.atan(self.sensor_mm / 2 / self.focal_mm))


def _check(pixels: int, rays: int, *, multiple: int = 2) -> None:
    if pixels < 16 or pixels % multiple:
        raise ValueError(f"pixels {pixels} must be a multiple of {multiple} and >= 16")
    if rays < 1:
        raise ValueError(f"rays {rays} must be >= 1")


def _chart_hits(cam: Camera, sensor_xy: np.ndarray, pupil_xy: np.ndarray,
                prism: tuple[int, int] | None) -> np.ndarray:
    """Chart points (..., 2) mm seen from sensor points (..., 2) mm through pupil points."""
    return optics_prism.scene_hits(sensor_xy, pupil_xy, image_distance_mm=cam.image_distance_mm,
                                   object_distance_mm=cam.object_distance_mm,
                                   prism=(cam.prism_n, cam.prism_apex_deg), towards=prism)


def sensor_point_seeing(cam: Camera, chart_xy: np.ndarray, *, region: tuple[int, int],
                        prism: tuple[int, int] | None) -> np.ndarray:
    """The sensor point (2,) mm whose ray through the region's pupil centroid (and prism) meets
    the chart at ``chart_xy`` (2,) mm: Newton iteration on the exact ray geometry."""
    pupil = optics_prism.pupil_centroid_mm(cam.aperture_mm, region)[None]
    s = -np.asarray(chart_xy, dtype=np.float64) * cam.image_distance_mm / cam.object_distance_mm
    for _ in range(30):
        f0 = _chart_hits(cam, s[None], pupil, prism)[0] - chart_xy
        h = 1e-6
        jac = np.column_stack([(_chart_hits(cam, (s + [h, 0])[None], pupil, prism)[0]
                                - chart_xy - f0) / h,
                               (_chart_hits(cam, (s + [0, h])[None], pupil, prism)[0]
                                - chart_xy - f0) / h])
        step = np.linalg.solve(jac, f0)
        s = s - step
        if np.max(np.abs(step)) < 1e-12:
            break
    return s


def _pupil_samples(rng, shape, region: tuple[int, int], radius: float, rays: int) -> np.ndarray:
    """Pupil points (rays, *shape, 2): uniform over the pupil part ``region`` = (sx, sy) with
    sx, sy in {-1, 0, +1} (0: the whole extent on that axis); the part's centroid when rays = 1."""
    sx, sy = region
    if rays == 1:
        centroid = optics_prism.pupil_centroid_mm(2 * radius, region)
        return np.broadcast_to(centroid, (1, *shape, 2)).copy()
    out = np.empty((rays, *shape, 2))
    for k in range(rays):
        out[k] = _pupil_draw(rng, shape, region, radius)
    return out


def _pupil_draw(rng, shape, region: tuple[int, int], radius: float) -> np.ndarray:
    """One pupil point (*shape, 2) per pixel, uniform over the pupil part ``region``."""
    sx, sy = region
    r = radius * np.sqrt(rng.random(shape))
    phi = 2 * math.pi * rng.random(shape)
    x, y = np.abs(r * np.cos(phi)), np.abs(r * np.sin(phi))
    return np.stack([sx * x if sx else r * np.cos(phi), sy * y if sy else r * np.sin(phi)],
                    axis=-1)


@dataclass(frozen=True)
class Chart:
    """The chart texture: ``image`` (rows, cols, 3) uint8 covering ``half_mm`` either side of
    the optical axis (a square, centred on the axis)."""

    image: np.ndarray
    half_mm: float

    @property
    def px_per_mm(self) -> float:
        return self.image.shape[1] / (2 * self.half_mm)


def make_chart(cam: Camera, view_pixels: int, *, seed: int, scene: str) -> Chart:
    """A chart square of +-45 deg at the chart distance, sampled a little finer than the views."""
    half_mm = cam.object_distance_mm  # tan(45 deg): covers the extended field with margin
    mm_per_view_px = 2 * cam.object_distance_mm * math.tan(math.radians(cam.half_field_deg)) \
        / view_pixels
    size = int(min(6000, max(64, math.ceil(2 * half_mm / mm_per_view_px * 1.2))))
    if scene == "white":
        img = np.full((size, size, 3), 255, np.uint8)
    elif scene == "chart":
        img = test_chart_u8(size, size, seed=seed, cells_across=16)
    else:
        raise ValueError(f"scene {scene!r}: use 'chart' or 'white'")
    return Chart(img, half_mm)


def _sample_chart(chart: Chart, xy_mm: np.ndarray) -> np.ndarray:
    """Bilinear chart colour (..., 3) float32 in [0, 1] at chart points (..., 2) mm."""
    shape = xy_mm.shape[:-1]
    col = (xy_mm[..., 0] + chart.half_mm) * chart.px_per_mm - 0.5
    row = (xy_mm[..., 1] + chart.half_mm) * chart.px_per_mm - 0.5
    bad = ~np.isfinite(col) | ~np.isfinite(row)
    # cv2.remap wants 2-D maps under 32767 columns: lay the points out 1024 to a row.
    flat = col.size
    padded = -(-flat // 1024) * 1024
    mx = np.full(padded, -10, np.float32)
    my = np.full(padded, -10, np.float32)
    mx[:flat] = np.where(bad, -10, col).ravel()
    my[:flat] = np.where(bad, -10, row).ravel()
    res = cv2.remap(chart.image, mx.reshape(-1, 1024), my.reshape(-1, 1024), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=(0, 0, 0))
    out = res.reshape(-1, 3)[:flat].astype(np.float32) / 255.0
    return out.reshape(*shape, 3)


def _view_centres(cam: Camera, rows: int, cols: int, cell_mm: float) -> tuple[np.ndarray, ...]:
    """Sensor x (cols,) and y (rows,) of view-pixel centres (mm from the optical axis)."""
    x = (np.arange(cols) + 0.5) * cell_mm - cols * cell_mm / 2
    y = (np.arange(rows) + 0.5) * cell_mm - rows * cell_mm / 2
    return x, y


def render_view(cam: Camera, chart: Chart, *, rows: int, cols: int, cell_mm: float,
                region: tuple[int, int], prism: tuple[int, int] | None, rays: int,
                rng: np.random.Generator, block_rows: int = 256) -> np.ndarray:
    """One view (rows, cols, 3) float32: the chart seen through pupil ``region`` and ``prism``.

    Each view pixel averages ``rays`` rays jittered over its sensor cell (``cell_mm`` square)
    and over the pupil region (its centroid when rays = 1).
    """
    xs, ys = _view_centres(cam, rows, cols, cell_mm)
    out = np.zeros((rows, cols, 3), np.float32)
    radius = cam.aperture_mm / 2
    for r0 in range(0, rows, block_rows):
        yb = ys[r0:r0 + block_rows]
        gx, gy = np.meshgrid(xs, yb)
        acc = np.zeros((len(yb), cols, 3), np.float32)
        centroid = _pupil_samples(rng, gx.shape, region, radius, 1)[0] if rays == 1 else None
        for _ in range(rays):  # one ray a pixel at a time: memory does not grow with --rays
            if rays > 1:
                pupil = _pupil_draw(rng, gx.shape, region, radius)
                jx = (rng.random(gx.shape) - 0.5) * cell_mm
                jy = (rng.random(gx.shape) - 0.5) * cell_mm
            else:
                pupil, jx, jy = centroid, 0.0, 0.0
            s = np.stack([gx + jx, gy + jy], axis=-1)
            acc += _sample_chart(chart, _chart_hits(cam, s, pupil, prism))
        out[r0:r0 + len(yb)] = acc / rays
    return out


def view_footprint(cam: Camera, *, rows: int, cols: int, cell_mm: float,
                   region: tuple[int, int], prism: tuple[int, int] | None) -> dict:
    """Chart area a view covers, traced through the pupil region's centroid.

    ``corners_mm`` (4, 2) and ``centre_mm`` are chart points; ``field_x_deg`` is the angular
    range (deg) between the view's left and right edge midpoints (the horizontal through the
    view centre), ``field_y_deg`` between its top and bottom edge midpoints; ``corner_x_deg`` /
    ``corner_y_deg`` the ranges over the four corners (larger: prisms stretch the corners).
    """
    w, h = cols * cell_mm / 2, rows * cell_mm / 2
    pts = np.array([[-w, -h], [w, -h], [w, h], [-w, h],  # corners
                    [-w, 0.0], [w, 0.0], [0.0, -h], [0.0, h], [0.0, 0.0]])
    pupil = np.tile(optics_prism.pupil_centroid_mm(cam.aperture_mm, region), (len(pts), 1))
    hits = _chart_hits(cam, pts, pupil, prism)
    if not np.isfinite(hits).all():
        # the same prism model as `plenocli optics` (optics.prism.deviate): NaN = reflected
        raise ValueError(f"the prism of index {cam.prism_n:g} and apex {cam.prism_apex_deg:g} "
                         f"deg reflects totally the light of pupil part {list(region)} that "
                         "reaches the view's edges: no image forms there; use a smaller "
                         "prism_apex_deg")
    ang = np.degrees(np.arctan(hits / cam.object_distance_mm))

    def span(values):
        return sorted([float(values[0]), float(values[1])])

    return {"corners_mm": hits[:4].tolist(), "centre_mm": hits[8].tolist(),
            "field_x_deg": span(ang[4:6, 0]), "field_y_deg": span(ang[6:8, 1]),
            "corner_x_deg": [float(ang[:4, 0].min()), float(ang[:4, 0].max())],
            "corner_y_deg": [float(ang[:4, 1].min()), float(ang[:4, 1].max())],
            "centre_deg": ang[8].tolist()}


def _prism_for(region, prisms: bool):
    return region if prisms else None


QUAD_REGIONS = {(0, 0): (1, 1), (0, 1): (-1, 1), (1, 0): (1, -1), (1, 1): (-1, -1)}


def render_quadpixel(*, pixels: int = 256, rays: int = 1, seed: int = 0, prisms: bool = True,
                     scene: str = "chart", open_quarters: tuple[tuple[int, int], ...] | None
                     = None, crosstalk: float = 0.0, camera: Camera = Camera()
                     ) -> tuple[np.ndarray, dict]:
    """An ideal quad-pixel capture (pixels, pixels, 3) float32 behind a pyramid of four prisms.

    ``open_quarters`` lists the SAIs (i, j) whose pupil quarter is open (None: all), for
    masked-pupil captures; ``crosstalk`` leaks that fraction of each SAI's light into the three
    others (ground truth for the cross-talk stage: with one open quarter, r = crosstalk).
    The sensor keeps the paper's 3.6 mm side: ``pixels`` sets the pixel size (1.2 um at 3000).
    """
    _check(pixels, rays)
    if not 0 <= crosstalk < 1:
        raise ValueError(f"crosstalk {crosstalk} must be in [0, 1)")
    rng = np.random.default_rng(seed)
    half = pixels // 2
    cell = camera.sensor_mm / half  # a micro-lens (2 x 2 pixels) is one view pixel
    chart = make_chart(camera, half, seed=seed, scene=scene)
    views = np.zeros((2, 2, half, half, 3), np.float32)
    truth_views = []
    for (i, j), region in QUAD_REGIONS.items():
        is_open = open_quarters is None or (i, j) in [tuple(q) for q in open_quarters]
        prism = _prism_for(region, prisms)
        if is_open:
            views[i, j] = render_view(camera, chart, rows=half, cols=half, cell_mm=cell,
                                      region=region, prism=prism, rays=rays, rng=rng)
        truth_views.append({"sai": [i, j], "pupil_quarter_xy": list(region), "open": is_open,
                            "prism_towards_xy": list(prism) if prism else None,
                            **view_footprint(camera, rows=half, cols=half, cell_mm=cell,
                                             region=region, prism=prism)})
    if crosstalk:
        # Each SAI also receives `crosstalk` times the light meant for every other SAI, so
        # that with one open quarter r = max other / intended = crosstalk exactly.
        total = views.sum(axis=(0, 1))
        views = views + crosstalk * (total[None, None] - views)
    sensor = np.empty((pixels, pixels, 3), np.float32)
    for i in range(2):
        for j in range(2):
            sensor[i::2, j::2] = views[i, j]  # L(2k + i, 2l + j) = S_ij(k, l)
    fx = [v["field_x_deg"] for v in truth_views]
    fy = [v["field_y_deg"] for v in truth_views]
    truth = {
        "kind": "quadpixel-pyramid", "seed": seed, "pixels": pixels, "rays": rays,
        "pixel_um": 1e3 * camera.sensor_mm / pixels, "n": 2, "scene": scene,
        "prisms": prisms, "camera": asdict(camera),
        "image_distance_mm": camera.image_distance_mm,
        "main_lens_field_deg": 2 * camera.half_field_deg,
        "layout": "SAI (i, j) = frame[i::2, j::2]; pupil quarter xy: x right, y down",
        "views": truth_views,
        "stitched_field_deg": {"x": max(f[1] for f in fx) - min(f[0] for f in fx),
                               "y": max(f[1] for f in fy) - min(f[0] for f in fy)},
        "crosstalk": crosstalk,
        "full_scale_dn": FULL_SCALE_DN,
        "chart": {"half_mm": chart.half_mm, "px": chart.image.shape[0]},
    }
    return sensor, truth


def render_dualpixel(*, pixels: int = 384, rays: int = 1, seed: int = 0, prism: bool = True,
                     scene: str = "chart", open_halves: tuple[str, ...] = ("A", "B"),
                     crosstalk: float = 0.0, camera: Camera = Camera()
                     ) -> tuple[np.ndarray, np.ndarray, dict]:
    """An ideal dual-pixel capture: views A and B, each (rows, pixels, 3) float32 with rows =
    2/3 pixels (a 3:2 sensor of width ``camera.sensor_mm``).

    A (left photodiodes) sees the +x pupil half, behind a prism deviating towards +x when
    ``prism``; B sees the -x half. ``open_halves`` masks a pupil half for cross-talk captures;
    ``crosstalk`` adds that fraction of each half's light to the other (r = crosstalk).
    """
    _check(pixels, rays, multiple=6)
    if not 0 <= crosstalk < 1:
        raise ValueError(f"crosstalk {crosstalk} must be in [0, 1)")
    rng = np.random.default_rng(seed)
    rows = pixels * 2 // 3
    cell = camera.sensor_mm / pixels
    chart = make_chart(camera, pixels, seed=seed, scene=scene)
    regions = {"A": (1, 0), "B": (-1, 0)}
    prisms = {"A": (1, 0) if prism else None, "B": None}
    views, truth_views = {}, []
    for name, region in regions.items():
        is_open = name in open_halves
        views[name] = (render_view(camera, chart, rows=rows, cols=pixels, cell_mm=cell,
                                   region=region, prism=prisms[name], rays=rays, rng=rng)
                       if is_open else np.zeros((rows, pixels, 3), np.float32))
        truth_views.append({"view": name, "pupil_half_x": region[0], "open": is_open,
                            "prism": prisms[name] is not None,
                            **view_footprint(camera, rows=rows, cols=pixels, cell_mm=cell,
                                             region=region, prism=prisms[name])})
    a, b = views["A"], views["B"]
    if crosstalk:
        a, b = a + crosstalk * views["B"], b + crosstalk * views["A"]
    # Horizontal shift (pixels) of the chart between B and A at the view centres, and where
    # they overlap: the chart point B sees at its left-edge middle is seen by A `overlap` px
    # further right (the prism's distortion makes the two differ by a few pixels).
    shift_mm = truth_views[0]["centre_mm"][0] - truth_views[1]["centre_mm"][0]
    mm_per_px_on_chart = camera.object_distance_mm / camera.image_distance_mm * cell
    edge_b = np.array([[-pixels * cell / 2, 0.0]])
    target = _chart_hits(camera, edge_b, _pupil_samples(None, (1,), (-1, 0), camera.aperture_mm
                                                        / 2, 1)[0], None)[0]
    seen_by_a = sensor_point_seeing(camera, target, region=(1, 0), prism=prisms["A"])
    truth = {"kind": "dualpixel-prism", "seed": seed, "pixels": [rows, pixels], "rays": rays,
             "pixel_um": 1e3 * cell, "scene": scene, "prism": prism, "camera": asdict(camera),
             "views": truth_views, "crosstalk": crosstalk,
             "shift_a_minus_b_px": shift_mm / mm_per_px_on_chart,
             "overlap_shift_px": float((seen_by_a[0] - edge_b[0, 0]) / cell),
             "stitched_field_x_deg": max(v["field_x_deg"][1] for v in truth_views)
             - min(v["field_x_deg"][0] for v in truth_views)}
    return a, b, truth


def bayer_mosaic(rgb: np.ndarray, pattern: str = "RGGB") -> np.ndarray:
    """A CFA mosaic (rows, cols) of an RGB image (rows, cols, 3): one colour per pixel."""
    index = {"R": 0, "G": 1, "B": 2}
    out = np.empty(rgb.shape[:2], rgb.dtype)
    for k, letter in enumerate(pattern):
        i, j = divmod(k, 2)
        out[i::2, j::2] = rgb[i::2, j::2, index[letter]]
    return out


def hex_centres(rows: int, cols: int, *, pitch_px: float, rotation_rad: float,
                offset_px: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 2) as (x, y) pixels of a hexagonal lattice covering the image, and their
    lattice indices (n, 2) (i along base x, j along base y).

    Base vectors (pixels): b_x = pitch (cos r, sin r), b_y = pitch (cos(r + 60 deg),
    sin(r + 60 deg)); lens (i, j) is at (W/2, H/2) + offset + i b_x + j b_y.
    """
    bx = pitch_px * np.array([math.cos(rotation_rad), math.sin(rotation_rad)])
    by = pitch_px * np.array([math.cos(rotation_rad + math.pi / 3),
                              math.sin(rotation_rad + math.pi / 3)])
    origin = np.array([cols / 2 + offset_px[0], rows / 2 + offset_px[1]])
    reach = int(math.ceil(1.5 * max(rows, cols) / pitch_px)) + 2
    ii, jj = np.meshgrid(np.arange(-reach, reach + 1), np.arange(-reach, reach + 1))
    ij = np.stack([ii.ravel(), jj.ravel()], axis=1)
    xy = origin + ij[:, :1] * bx + ij[:, 1:] * by
    keep = ((xy[:, 0] > -pitch_px) & (xy[:, 0] < cols + pitch_px)
            & (xy[:, 1] > -pitch_px) & (xy[:, 1] < rows + pitch_px))
    return xy[keep], ij[keep]


def render_raytrix(*, pixels: int = 404, rays: int = 1, seed: int = 0, prism: bool = True,
                   scene: str = "chart", pitch_px: float = 20.2, g: float = 4.0,
                   lens_border_px: float = 1.0, camera: Camera = Camera()
                   ) -> tuple[np.ndarray, dict]:
    """A focused (type-2) plenoptic capture (rows, pixels) float32 in [0, 1], mono, with a prism
    over the +x pupil half.

    Pixel x under the micro-lens of centre c sees the main-lens image point c + g (x - c)
    (paper Eq. 3 with s = 1); its pupil point is on the -sign(x - c) side, so pixels left of
    their micro-lens centre see the prism-deviated field. The lattice is hexagonal with a
    seeded small rotation and offset, recorded RayCalibData-like in the truth.
    """
    _check(pixels, rays, multiple=2)
    if pitch_px < 4 or g <= 0:
        raise ValueError(f"pitch_px {pitch_px} must be >= 4 and g {g} > 0")
    rng = np.random.default_rng(seed)
    rows = pixels * 2 // 3
    cell = camera.sensor_mm / pixels  # main-lens image pixel (mm)
    rotation = float(rng.uniform(-0.01, 0.01))
    offset = (float(rng.uniform(-0.5, 0.5) * pitch_px), float(rng.uniform(-0.5, 0.5) * pitch_px))
    centres, ij = hex_centres(rows, pixels, pitch_px=pitch_px, rotation_rad=rotation,
                              offset_px=offset)
    # Nearest micro-lens of every pixel: look it up on a fine grid via a KD-tree.
    from scipy.spatial import cKDTree

    chart = make_chart(camera, pixels, seed=seed, scene=scene)
    tree = cKDTree(centres)
    out = np.zeros((rows, pixels), np.float32)
    luminance = np.array([0.2126, 0.7152, 0.0722], np.float32)
    radius = camera.aperture_mm / 2
    for r0 in range(0, rows, 128):
        yy, xx = np.mgrid[r0:min(rows, r0 + 128), 0:pixels].astype(np.float64)
        acc = np.zeros(yy.shape, np.float32)
        for _ in range(rays):
            jx = rng.random(xx.shape) - 0.5 if rays > 1 else 0.0
            jy = rng.random(xx.shape) - 0.5 if rays > 1 else 0.0
            px, py = xx + 0.5 + jx, yy + 0.5 + jy
            dist, nearest = tree.query(np.stack([px.ravel(), py.ravel()], axis=1))
            c = centres[nearest].reshape(*px.shape, 2)
            dx, dy = px - c[..., 0], py - c[..., 1]
            # Main-lens image point (pixels) and sensor position (mm from the axis).
            ix, iy = c[..., 0] + g * dx, c[..., 1] + g * dy
            s = np.stack([(ix - pixels / 2) * cell, (iy - rows / 2) * cell], axis=-1)
            # Pupil point: opposite to the pixel's offset, scaled to the pupil radius.
            half_pitch = pitch_px / 2
            pupil = np.stack([-dx / half_pitch * radius, -dy / half_pitch * radius], axis=-1)
            hits = np.empty_like(s)
            left = dx < 0  # these pixels see the +x pupil half: the prism's side
            hits[left] = _chart_hits(camera, s[left], pupil[left], (1, 0) if prism else None)
            hits[~left] = _chart_hits(camera, s[~left], pupil[~left], None)
            colour = _sample_chart(chart, hits) @ luminance
            r = dist.reshape(px.shape)
            edge = half_pitch - lens_border_px
            vignette = np.clip((edge - r) / 1.5 + 0.5, 0.0, 1.0)  # soft micro-lens border
            acc += colour * vignette
        out[r0:r0 + yy.shape[0]] = acc / rays
    base_x = [math.cos(rotation), math.sin(rotation)]
    base_y = [math.cos(rotation + math.pi / 3), math.sin(rotation + math.pi / 3)]
    deviated = _chart_hits(camera, np.zeros((1, 2)), np.array([[radius / 2, 0.0]]),
                           (1, 0) if prism else None)[0]
    truth = {
        "kind": "raytrix-prism", "seed": seed, "pixels": [rows, pixels], "rays": rays,
        "scene": scene, "prism": prism, "camera": asdict(camera), "g": g,
        "prism_view": "left (x - c < 0)",
        "prism_centre_shift_px": float(deviated[0] / camera.object_distance_mm
                                       * camera.image_distance_mm / cell),
        # RayCalibData-like lattice: offset from the image centre with y pointing up.
        "lattice": {"diameter": pitch_px, "rotation": rotation,
                    "offset": {"x": offset[0], "y": -offset[1]},
                    "lens_base_x": {"x": base_x[0], "y": -base_x[1]},
                    "lens_base_y": {"x": base_y[0], "y": -base_y[1]},
                    "lens_border": lens_border_px,
                    "centres_xy_px": centres.tolist() if len(centres) <= 20000 else None,
                    "indices_ij": ij.tolist() if len(centres) <= 20000 else None},
    }
    return out, truth
