"""Ghosts of a prism rig: a known, smooth mixing of the views, and its masked-pupil whites.

Every pixel of view k records ``sum_j M_kj(x, y) T_j(x, y)`` (``plenocli.unmix``). Here M is
known: ``M_jj = 1`` and, off the diagonal,

    M_kj(u, v) = r_kj * s_c * (1 + a_kj u + b_kj v + q (u^2 + v^2 - 1/6))

with u, v in [-1/2, 1/2] across the frame, ``a_kj, b_kj`` seeded in [-slope, slope], a small
curvature q and a colour scale ``s_c`` (cross-talk depends on wavelength). For four views
(quad-pixel), quarters that share an edge leak ``r``, the diagonal ones ``DIAGONAL * r``.

The clean per-view images come from ``plenocli.synth.prismcam`` (rendered without cross-talk);
this module mixes them, makes the whites with one pupil part open, and returns capture sets.
"""

from __future__ import annotations

import numpy as np

from plenocli.synth import prismcam
from plenocli.synth.capture import SimFile, Simulation

DIAGONAL = 0.4  # diagonal quarters of a quad-pixel leak less than edge neighbours
CURVATURE = 0.05
COLOUR_SCALE = {"R": 1.1, "G": 1.0, "B": 0.85, "L": 1.0}
CROSS_MASK_LIGHT = 0.84  # the paper's cross mask keeps 84 % of the light


def mixing_field(shape: tuple[int, int], *, n_views: int, r: float, slope: float = 0.2,
                 colours: tuple[str, ...] = ("L",), seed: int = 0) -> np.ndarray:
    """The known mixing, per pixel: (colours, V, V, rows, cols) float64 with M_jj = 1.

    Parameters
    ----------
    shape : (rows, cols) of a view.
    n_views : 2 (dual-pixel, Raytrix) or 4 (quad-pixel).
    r : cross-talk of the (edge-)neighbour views at the frame centre, green (e.g. 0.5, 0.13).
    slope : relative change of each M_kj across the frame (u or v from -1/2 to 1/2).
    colours : names of the colour planes (R, G, B or L).
    seed : seed of ``np.random.default_rng`` for the per-entry slopes.
    """
    if n_views not in (2, 4):
        raise ValueError(f"n_views must be 2 or 4, got {n_views}")
    if not 0 <= r < 1 or not 0 <= slope < 1:
        raise ValueError(f"r ({r}) and slope ({slope}) must be in [0, 1)")
    rng = np.random.default_rng(seed)
    rows, cols = shape
    v = (np.arange(rows) + 0.5)[:, None] / rows - 0.5
    u = (np.arange(cols) + 0.5)[None, :] / cols - 0.5
    field = np.zeros((len(colours), n_views, n_views, rows, cols))
    for k in range(n_views):
        field[:, k, k] = 1.0
        for j in range(n_views):
            if j == k:
                continue
            a, b = rng.uniform(-slope, slope, 2)
            diagonal = n_views == 4 and (k ^ j) == 3  # S00-S11, S01-S10
            shape_uv = 1 + a * u + b * v + CURVATURE * (u ** 2 + v ** 2 - 1 / 6)
            for c, colour in enumerate(colours):
                field[c, k, j] = r * (DIAGONAL if diagonal else 1.0) * COLOUR_SCALE[colour] \
                    * shape_uv
    return field


def colour_index(shape: tuple[int, int], cfa: str | None) -> np.ndarray:
    """(rows, cols) index into ("R", "G", "B") of each pixel of a ``cfa`` mosaic (0s if None)."""
    out = np.zeros(shape, np.int64)
    if cfa:
        for k, letter in enumerate(cfa.upper()):
            out[k // 2::2, k % 2::2] = "RGB".index(letter)
    return out


def apply_mixing(clean: np.ndarray, field: np.ndarray, colours: np.ndarray | None = None
                 ) -> np.ndarray:
    """Observed views (V, rows, cols): ``O_k = sum_j M_kj T_j`` per pixel.

    ``clean`` (V, rows, cols); ``field`` (C, V, V, rows, cols); ``colours`` (rows, cols) colour
    index of each pixel (None: colour 0).
    """
    per_pixel = _pick_colour(field, colours)
    return np.einsum("kjyx,jyx->kyx", per_pixel, clean)


def masked_white(whites: np.ndarray, field: np.ndarray, part: int,
                 colours: np.ndarray | None = None) -> np.ndarray:
    """Views (V, rows, cols) of a white target with only pupil part ``part`` open:
    ``O_k = M_k,part W_part`` (``whites`` (V, rows, cols): each view's own white)."""
    per_pixel = _pick_colour(field, colours)
    return per_pixel[:, part] * whites[part]


def _pick_colour(field: np.ndarray, colours: np.ndarray | None) -> np.ndarray:
    if colours is None:
        return field[0]
    return np.take_along_axis(field, colours[None, None, None], axis=0)[0]


def tile_truth(field: np.ndarray, whites: np.ndarray, tile_px: int,
               colours: np.ndarray | None = None) -> np.ndarray:
    """The flux-weighted mean of the true M_kj over each tile (what a masked white measures),
    (C, V, V, n_tile_rows, n_tile_cols): for comparison with ``measure_mixing``."""
    n_c, n_v, _, rows, cols = field.shape
    n_r, n_k = -(-rows // tile_px), -(-cols // tile_px)
    out = np.empty((n_c, n_v, n_v, n_r, n_k))
    cidx = np.zeros((rows, cols), np.int64) if colours is None else colours
    for c in range(n_c):
        sel = cidx == c
        for j in range(n_v):
            weight = np.where(sel, whites[j], 0.0)
            denom = _tile_sum(weight, tile_px)
            for k in range(n_v):
                out[c, k, j] = _tile_sum(weight * field[c, k, j], tile_px) / denom
    return out


def _tile_sum(values: np.ndarray, tile_px: int) -> np.ndarray:
    rows, cols = values.shape
    n_r, n_k = -(-rows // tile_px), -(-cols // tile_px)
    padded = np.zeros((n_r * tile_px, n_k * tile_px))
    padded[:rows, :cols] = values
    return padded.reshape(n_r, tile_px, n_k, tile_px).sum(axis=(1, 3))


# ---------------------------------------------------------------------------------------------
# Capture sets: the ghosted capture, the same capture without ghosts (the truth), one masked
# white per pupil part and an all-open white (for the flat), as the real cameras write them.

def render_dualpixel_ghost(*, pixels: int = 384, rays: int = 1, seed: int = 0, r: float = 0.5,
                           slope: float = 0.2, prism_apex_deg: float = 30.0) -> dict:
    """Clean and ghosted A, B mosaics (RGGB) of a dual-pixel + prism capture, plus whites.

    Returns a dict of (rows, cols) float64 arrays in [0, ~1.5]: ``clean`` and ``ghosted``
    (2, rows, cols) views A, B; ``masked`` {"A": (2, rows, cols), "B": ...}; ``white``
    (2, rows, cols) all-open white with its ghosts; ``field`` (3, 2, 2, rows, cols) the true M.
    """
    cam = prismcam.Camera(prism_apex_deg=prism_apex_deg)
    a, b, truth = prismcam.render_dualpixel(pixels=pixels, rays=rays, seed=seed, prism=True,
                                            camera=cam)
    wa, wb, _ = prismcam.render_dualpixel(pixels=pixels, rays=rays, seed=seed, prism=False,
                                          scene="white", camera=cam)
    mosaic = [prismcam.bayer_mosaic(v).astype(np.float64) for v in (a, b, wa, wb)]
    clean, whites = np.stack(mosaic[:2]), np.stack(mosaic[2:])
    colours = colour_index(clean.shape[1:], "RGGB")
    field = mixing_field(clean.shape[1:], n_views=2, r=r, slope=slope, colours=("R", "G", "B"),
                         seed=seed + 7)
    return {"clean": clean, "ghosted": apply_mixing(clean, field, colours),
            "masked": {name: masked_white(whites, field, j, colours)
                       for j, name in enumerate("AB")},
            "white": apply_mixing(whites, field, colours), "field": field, "render": truth}


def render_quadpixel_ghost(*, pixels: int = 256, rays: int = 1, seed: int = 0, r: float = 0.13,
                           slope: float = 0.2, cross_mask: bool = False) -> dict:
    """Clean and ghosted SAIs of a quad-pixel + pyramid capture (RGB), plus masked whites.

    With ``cross_mask`` the paper's cross-shaped mask is in the stop: r = 3 % and 84 % of the
    light. Returns ``clean``/``ghosted`` (4, half, half, 3) SAIs S00, S01, S10, S11; ``masked``
    {name: (4, half, half, 3)}; ``field`` (3, 4, 4, half, half).
    """
    light = CROSS_MASK_LIGHT if cross_mask else 1.0
    r_used = 0.03 if cross_mask else r
    sensor, truth = prismcam.render_quadpixel(pixels=pixels, rays=rays, seed=seed)
    white, _ = prismcam.render_quadpixel(pixels=pixels, rays=rays, seed=seed, prisms=False,
                                         scene="white")
    clean = light * _sais(sensor)
    whites = light * _sais(white)
    half = clean.shape[1]
    field = mixing_field((half, half), n_views=4, r=r_used, slope=slope,
                         colours=("R", "G", "B"), seed=seed + 7)
    ghosted = np.stack([apply_mixing(clean[..., c], field[c:c + 1]) for c in range(3)], -1)
    masked = {name: np.stack([masked_white(whites[..., c], field[c:c + 1], j)
                              for c in range(3)], -1)
              for j, name in enumerate(SAI_NAMES)}
    return {"clean": clean, "ghosted": ghosted, "masked": masked, "field": field,
            "r": r_used, "light": light, "render": truth}


SAI_NAMES = ("S00", "S01", "S10", "S11")


def _sais(sensor: np.ndarray) -> np.ndarray:
    """The four SAIs (4, half, half, 3) of a quad-pixel sensor image: S_ij = L[i::2, j::2]."""
    return np.stack([sensor[i::2, j::2] for i in range(2) for j in range(2)]).astype(np.float64)


def _multiplex(sais: np.ndarray) -> np.ndarray:
    rows, cols = sais.shape[1:3]
    sensor = np.empty((2 * rows, 2 * cols, 3), np.float64)
    for k in range(4):
        sensor[k // 2::2, k % 2::2] = sais[k]
    return sensor


def _canon_dng(name: str, views: np.ndarray, *, scale: float, rng, noise_dn: float) -> SimFile:
    """Two CFA frames S = A + B and A like the dual-pixel prism capture (black 512, white
    16383, 16 optical-black columns)."""
    black, white, margin = 512, 16383, 16
    rows, cols = views.shape[1:]
    frames = np.full((2, rows, cols + margin), float(black))
    frames[0, :, margin:] += (views[0] + views[1]) * scale
    frames[1, :, margin:] += views[0] * scale
    if noise_dn > 0:
        frames += rng.normal(0.0, noise_dn, frames.shape)
    data = np.clip(np.round(frames), 0, white).astype(np.uint16)
    return SimFile(name, data, "dng", dict(
        cfa="RGGB", black_levels=[black, black], white_level=white,
        active_area=[0, margin, rows, cols + margin], masked_areas=[[0, 0, rows, margin]],
        frame_names=["S", "A"]))


def _uint16_tiff(name: str, data: np.ndarray, photometric: str) -> SimFile:
    return SimFile(name, np.clip(np.round(data), 0, 65535).astype(np.uint16), "tiff",
                   {"photometric": photometric})


def simulate_dualpixel_ghost(*, seed: int = 0, pixels: int = 384, rays: int = 1,
                             r: float = 0.5, slope: float = 0.2, noise_dn: float = 0.0,
                             prism_apex_deg: float = 30.0) -> Simulation:
    """A Canon-like dual-pixel + prism set with ghosts (r about 50 %):
    ``capture.dng`` (ghosted), ``clean.dng`` (the same capture without ghosts: the truth),
    ``white.dng`` (all-open white, for flat), ``masked_A.dng`` / ``masked_B.dng`` (only pupil
    half A / B open) and ``truth.json``."""
    sim = render_dualpixel_ghost(pixels=pixels, rays=rays, seed=seed, r=r, slope=slope,
                                 prism_apex_deg=prism_apex_deg)
    scale = 0.25 * (16383 - 512)  # S of a ghosted white stays below clipping up to r ~ 0.9
    rng = np.random.default_rng(seed + 1)
    files = {"capture": sim["ghosted"], "clean": sim["clean"], "white": sim["white"],
             "masked_A": sim["masked"]["A"], "masked_B": sim["masked"]["B"]}
    written = tuple(_canon_dng(f"{name}.dng", views, scale=scale, rng=rng, noise_dn=noise_dn)
                    for name, views in files.items())
    truth = _truth(sim["field"], ("A", "B"), kind="dualpixel-ghost", seed=seed, r=r,
                   slope=slope, noise_dn=noise_dn, scale_dn=scale,
                   files={k: f"{k}.dng" for k in files}, render=sim["render"])
    return Simulation(written, truth)


def simulate_quadpixel_ghost(*, seed: int = 0, pixels: int = 256, rays: int = 1,
                             r: float = 0.13, slope: float = 0.2, cross_mask: bool = False,
                             noise_dn: float = 0.0) -> Simulation:
    """A quad-pixel + pyramid set with ghosts (r = 13 %, or 3 % with ``cross_mask``):
    ``capture.tif`` (16-bit RGB, ghosted), ``clean.tif`` (the truth), ``masked_S00.tif`` ..
    ``masked_S11.tif`` (one pupil quarter open) and ``truth.json``."""
    sim = render_quadpixel_ghost(pixels=pixels, rays=rays, seed=seed, r=r, slope=slope,
                                 cross_mask=cross_mask)
    scale = 0.6 * prismcam.FULL_SCALE_DN  # a ghosted white (1 + 3 r) stays below 65535
    rng = np.random.default_rng(seed + 1)
    files = {"capture": sim["ghosted"], "clean": sim["clean"],
             **{f"masked_{n}": sim["masked"][n] for n in SAI_NAMES}}
    written = []
    for name, sais in files.items():
        data = _multiplex(sais) * scale
        if noise_dn > 0:
            data = data + rng.normal(0.0, noise_dn, data.shape)
        written.append(_uint16_tiff(f"{name}.tif", data, "rgb"))
    truth = _truth(sim["field"], SAI_NAMES, kind="quadpixel-ghost", seed=seed, r=sim["r"],
                   slope=slope, noise_dn=noise_dn, scale_dn=scale, cross_mask=cross_mask,
                   light=sim["light"], files={k: f"{k}.tif" for k in files},
                   render=sim["render"])
    return Simulation(tuple(written), truth)


def _truth(field: np.ndarray, views: tuple[str, ...], **extra) -> dict:
    """truth.json: the parameters, and r = max over k != j of M_kj / M_jj per colour."""
    off = ~np.eye(field.shape[1], dtype=bool)  # M_jj = 1: the ratios are the entries
    r_max = {c: float(field[k][off].max()) for k, c in enumerate("RGB"[:field.shape[0]])}
    return {**extra, "views": list(views), "colours": ["R", "G", "B"],
            "mixing_r_max_per_colour": r_max,
            "model": "O_k = sum_j M_kj T_j per pixel, M_jj = 1 (plenocli.synth.mixing)"}


# ---------------------------------------------------------------------------------------------
# Raytrix + prism. prismcam.render_raytrix gives each pixel only the field of its own pupil
# half; cross-talk needs both fields at every pixel, so this renderer (the same optics) computes
# both. It belongs in prismcam (render_raytrix with a pupil-edge blur) once that module settles.

def render_raytrix_ghost(*, pixels: int = 404, seed: int = 0, pitch_px: float = 20.2,
                         g: float = 4.0, edge_blur_px: float = 1.5, lens_border_px: float = 1.0,
                         scene: str = "chart", camera: prismcam.Camera | None = None) -> dict:
    """A focused (type-2) capture with a prism over the +x pupil half, with and without
    cross-talk, and its whites: dict of (rows, pixels) float64 images in [0, 1].

    Pixel x under the micro-lens of centre c sees image point c + g (x - c) (the lattice is
    ``prismcam.render_raytrix``'s for the same seed). Without cross-talk, pixels left of c see
    the +x (prism) pupil half only. With it, the pupil edge is blurred over ``edge_blur_px``
    (micro-lens aberrations, pixel size): a pixel at dx = x - c collects the fraction
    ``w(dx) = erfc(dx / (sqrt 2 blur)) / 2`` of its light through the prism half.

    Returns ``ghosted``, ``clean``, ``white`` (all-open white), ``masked_left`` (only the
    prism half open), ``masked_right`` (only the other half open).
    """
    from scipy.spatial import cKDTree
    from scipy.special import erfc

    prismcam._check(pixels, 1)  # the sizes render_raytrix takes: its lattice is this one's
    camera = camera or prismcam.Camera()
    rng = np.random.default_rng(seed)
    rows = pixels * 2 // 3
    cell = camera.sensor_mm / pixels
    rotation = float(rng.uniform(-0.01, 0.01))
    offset = (float(rng.uniform(-0.5, 0.5) * pitch_px), float(rng.uniform(-0.5, 0.5) * pitch_px))
    centres, _ = prismcam.hex_centres(rows, pixels, pitch_px=pitch_px, rotation_rad=rotation,
                                      offset_px=offset)
    chart = prismcam.make_chart(camera, pixels, seed=seed, scene=scene)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    radius, half_pitch = camera.aperture_mm / 2, pitch_px / 2
    yy, xx = np.mgrid[0:rows, 0:pixels].astype(np.float64) + 0.5
    dist, nearest = cKDTree(centres).query(np.stack([xx.ravel(), yy.ravel()], axis=1))
    c = centres[nearest].reshape(rows, pixels, 2)
    dx, dy = xx - c[..., 0], yy - c[..., 1]
    s = np.stack([(c[..., 0] + g * dx - pixels / 2) * cell,
                  (c[..., 1] + g * dy - rows / 2) * cell], axis=-1)
    px = np.abs(dx) / half_pitch * radius
    py = -dy / half_pitch * radius
    fields = []
    for side, prism in ((1, (1, 0)), (-1, None)):  # +x half behind the prism, -x half bare
        pupil = np.stack([side * px, py], axis=-1)
        hits = prismcam._chart_hits(camera, s, pupil, prism)
        fields.append(prismcam._sample_chart(chart, hits).astype(np.float64) @ luminance)
    prism_field, bare_field = fields
    vignette = np.clip((half_pitch - lens_border_px - dist.reshape(rows, pixels)) / 1.5 + 0.5,
                       0.0, 1.0)
    w = 0.5 * erfc(dx / (np.sqrt(2) * edge_blur_px)) if edge_blur_px > 0 else \
        (dx < 0).astype(np.float64)
    hard = (dx < 0).astype(np.float64)
    return {"ghosted": vignette * (w * prism_field + (1 - w) * bare_field),
            "clean": vignette * (hard * prism_field + (1 - hard) * bare_field),
            "white": vignette, "masked_left": vignette * w, "masked_right": vignette * (1 - w),
            "lattice": {"rotation": rotation, "offset_px": list(offset), "pitch_px": pitch_px}}


def simulate_raytrix_ghost(*, seed: int = 0, pixels: int = 404, pitch_px: float = 20.2,
                           edge_blur_px: float = 1.5, noise_dn: float = 0.0) -> Simulation:
    """A Raytrix + prism set with cross-talk: ``capture.tif`` (16-bit mono), ``clean.tif``
    (the truth), ``white.tif``, ``masked_left.tif`` (prism half open), ``masked_right.tif``
    and ``truth.json``."""
    sim = render_raytrix_ghost(pixels=pixels, seed=seed, pitch_px=pitch_px,
                               edge_blur_px=edge_blur_px)
    rng = np.random.default_rng(seed + 1)
    names = ("capture", "clean", "white", "masked_left", "masked_right")
    written = []
    for name, key in zip(names, ("ghosted", "clean", "white", "masked_left", "masked_right"),
                         strict=True):
        data = sim[key] * prismcam.FULL_SCALE_DN
        if noise_dn > 0:
            data = data + rng.normal(0.0, noise_dn, data.shape)
        written.append(_uint16_tiff(f"{name}.tif", data, "minisblack"))
    truth = {"kind": "raytrix-ghost", "seed": seed, "pixels": [pixels * 2 // 3, pixels],
             "edge_blur_px": edge_blur_px, "noise_dn": noise_dn, "lattice": sim["lattice"],
             "files": {n: f"{n}.tif" for n in names},
             "model": "pixel = w(dx) prism field + (1 - w(dx)) bare field, w = erfc(dx / "
                      "(sqrt 2 blur)) / 2 (plenocli.synth.mixing)"}
    return Simulation(tuple(written), truth)
