"""Capture sets of the paper's prism designs (``plenocli simulate quadpixel-pyramid`` ...): the
renders of :mod:`plenocli.synth.prismcam` quantised to the raw formats decode reads, with their
truth. Pure: the ``simulate`` stage writes the files."""

from __future__ import annotations

import numpy as np

from plenocli.synth.capture import SimFile, Simulation
from plenocli.synth.prismcam import (
    FULL_SCALE_DN,
    Camera,
    bayer_mosaic,
    render_dualpixel,
    render_quadpixel,
    render_raytrix,
)


def _to_u16(image: np.ndarray, scale: float, *, noise_dn: float, rng) -> np.ndarray:
    data = image * scale
    if noise_dn > 0:
        data = data + rng.normal(0.0, noise_dn, data.shape)
    return np.clip(np.round(data), 0, 65535).astype(np.uint16)


def simulate_quadpixel(*, seed: int = 0, pixels: int = 256, rays: int = 1,
                       no_prisms: bool = False, scene: str = "chart",
                       open_quarters: str | None = None, crosstalk: float = 0.0,
                       noise_dn: float = 0.0, prism_apex_deg: float = 16.7) -> Simulation:
    """``capture.tif`` (16-bit RGB, pixels x pixels: decode gives frames R, G, B) and its truth.

    ``open_quarters``: SAIs whose pupil quarter is open, e.g. "00" or "00,11" (None: all).
    """
    quarters = None
    if open_quarters:
        try:
            quarters = tuple((int(q[0]), int(q[1])) for q in open_quarters.split(","))
        except (ValueError, IndexError) as err:
            raise ValueError(f"open_quarters {open_quarters!r}: give SAIs like 00,11") from err
    cam = Camera(prism_apex_deg=prism_apex_deg)
    sensor, truth = render_quadpixel(pixels=pixels, rays=rays, seed=seed, prisms=not no_prisms,
                                     scene=scene, open_quarters=quarters, crosstalk=crosstalk,
                                     camera=cam)
    data = _to_u16(sensor, FULL_SCALE_DN, noise_dn=noise_dn, rng=np.random.default_rng(seed + 1))
    truth.update(files={"capture": "capture.tif"}, noise_dn=noise_dn)
    return Simulation((SimFile("capture.tif", data, "tiff", {"photometric": "rgb"}),), truth)


def simulate_dualpixel(*, seed: int = 0, pixels: int = 384, rays: int = 1,
                       no_prisms: bool = False, scene: str = "chart", open_halves: str = "A,B",
                       crosstalk: float = 0.0, noise_dn: float = 2.0,
                       prism_apex_deg: float = 30.0) -> Simulation:
    """``capture.dng`` (two CFA frames "S" = A + B and "A", like a Canon DPRAW, RGGB, black
    512, white 16383, 16 optical-black columns on the left) and its truth.

    The default prism (n = 1.74, A = 30 deg) deviates the A view by ~78 % of the frame width,
    so that A and B are "almost juxtaposed with a tiny common portion" as in the paper's
    prototypes (22 % overlap here, enough to register them); the stitched field is 64 deg.
    """
    halves = tuple(h.strip() for h in open_halves.split(","))
    if set(halves) - {"A", "B"}:
        raise ValueError(f"open_halves {open_halves!r}: use A, B or A,B")
    a, b, truth = render_dualpixel(pixels=pixels, rays=rays, seed=seed, prism=not no_prisms,
                                   scene=scene, open_halves=halves, crosstalk=crosstalk,
                                   camera=Camera(prism_apex_deg=prism_apex_deg))
    rng = np.random.default_rng(seed + 1)
    black, white, margin = 512, 16383, 16
    scale = 0.4 * (white - black)  # a white chart through one half: 40 % of the range
    rows, cols = a.shape[:2]
    frames = np.empty((2, rows, cols + margin), np.float64)
    for k, view in enumerate((a + b, a)):
        frames[k, :, margin:] = bayer_mosaic(view) * scale + black
        frames[k, :, :margin] = black
    frames += rng.normal(0.0, noise_dn, frames.shape) if noise_dn > 0 else 0.0
    data = np.clip(np.round(frames), 0, white).astype(np.uint16)
    active = [0, margin, rows, cols + margin]
    dng = {"cfa": "RGGB", "black_levels": [black, black], "white_level": white,
           "active_area": active, "masked_areas": [[0, 0, rows, margin]],
           "frame_names": ["S", "A"]}
    truth.update(files={"capture": "capture.dng"}, black_level=black, white_level=white,
                 scale_dn=scale, cfa="RGGB", active_area=active, noise_dn=noise_dn)
    return Simulation((SimFile("capture.dng", data, "dng", dng),), truth)


def simulate_raytrix(*, seed: int = 0, pixels: int = 404, rays: int = 1, no_prisms: bool = False,
                     scene: str = "chart", pitch_px: float = 20.2,
                     noise_dn: float = 0.0) -> Simulation:
    """``capture.tif`` (16-bit mono sensor image) and its truth (with the lattice)."""
    image, truth = render_raytrix(pixels=pixels, rays=rays, seed=seed, prism=not no_prisms,
                                  scene=scene, pitch_px=pitch_px)
    data = _to_u16(image, FULL_SCALE_DN, noise_dn=noise_dn, rng=np.random.default_rng(seed + 1))
    truth.update(files={"capture": "capture.tif"}, noise_dn=noise_dn,
                 full_scale_dn=FULL_SCALE_DN)
    return Simulation((SimFile("capture.tif", data, "tiff", {"photometric": "minisblack"}),),
                      truth)
