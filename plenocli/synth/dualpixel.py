"""Canon-like dual-pixel captures (5D Mark IV DPRAW layout) with ground truth.

A capture is a two-frame raw: frame 0 is the sum S = A + B, frame 1 the left half-pixel A. Both
carry a left over-scan (columns ``[0, left)``) and a top over-scan (rows ``[0, top)``) whose bias
varies per row and per CFA colour exactly as in the active area. The A/S split varies across the
frame (left-right falloff, colour-dependent), as on the real camera; a main-lens vignetting darkens
the corners; bright spots clip S. With ``noise=0`` everything is integer-valued and exact.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from plenocli.synth.capture import SimFile, Simulation

COLOUR_GAIN = {"R": 0.55, "G": 1.0, "B": 0.7}  # white target seen through the CFA
SPLIT_SLOPE = {"R": 0.16, "G": 0.12, "B": 0.09}  # A/S change from the left to the right edge
CFA_OFFSET = {"R": 6, "G": 0, "B": -4}  # per-colour bias offsets (DN)


def dualpixel_capture(*, seed: int = 0, rows: int = 192, cols: int = 256, top: int = 16,
                      left: int = 64, scene: str = "chart", cfa: str = "RGGB",
                      black: tuple[int, int] = (2048, 2036), bias_amplitude: float = 9.0,
                      white_level: int = 15000, signal: float = 6000.0,
                      noise: float = 2.0) -> tuple[np.ndarray, dict]:
    """One dual-pixel raw and its truth.

    Parameters
    ----------
    rows, cols : active area size (pixels, even); ``top``, ``left``: over-scan margins (even,
        so that the CFA phase of the active area is the one of the raw).
    scene : "chart" (texture, edges and clipping highlights) or "white" (a uniform target).
    black : bias level (DN) of frame 0 and frame 1, before the per-row, per-colour variation.
    signal : mean level (DN) of the sum S at the centre of the white target.
    noise : read noise (DN, Gaussian) per frame; 0 gives a noiseless, integer-exact capture
        (photon noise is on whenever ``noise > 0``).

    Returns
    -------
    raw : ndarray uint16, (2, top + rows, left + cols)
        Frame 0 = S, frame 1 = A, with over-scan.
    truth : dict
        Arrays ``A``, ``B``, ``S`` (active area, DN above black, NaN where clipped),
        ``row_bias`` (2, top + rows, 2): bias of each frame, row and column phase (DN),
        ``split`` (A/S of the active area), ``vignetting``, masks ``clipped_S``, ``clipped_A``,
        and the geometry.
    """
    if rows % 2 or cols % 2 or top % 2 or left % 2:
        raise ValueError("rows, cols, top and left must be even to keep the CFA phase")
    rng = np.random.default_rng(seed)
    height, width = top + rows, left + cols
    colour = np.array([[cfa[0], cfa[1]], [cfa[2], cfa[3]]])
    rr, cc = np.ogrid[0:rows, 0:cols]
    gain = np.vectorize(COLOUR_GAIN.get)(colour)[rr % 2, cc % 2]  # per-pixel via the 2 x 2 cell
    slope = np.vectorize(SPLIT_SLOPE.get)(colour)[rr % 2, cc % 2]

    xn = (cc - (cols - 1) / 2) / (cols / 2)
    yn = (rr - (rows - 1) / 2) / (rows / 2)
    vignetting = 1.0 - 0.3 * (xn**2 + yn**2) / 2
    split = 0.5 - slope * xn + 0.02 * yn  # A is brighter on the left of the frame

    radiance = _radiance(rng, scene, rows, cols)

    s_mean = signal * radiance * vignetting * gain
    a_mean = split * s_mean
    b_mean = s_mean - a_mean
    if noise > 0:
        a_sig = rng.poisson(a_mean).astype(np.float64)
        b_sig = rng.poisson(b_mean).astype(np.float64)
    else:
        a_sig, b_sig = np.round(a_mean), np.round(b_mean)

    raw, row_bias, clipped = _frames(rng, (a_sig + b_sig, a_sig), colour, black=black,
                                     top=top, left=left, bias_amplitude=bias_amplitude,
                                     white_level=white_level, noise=noise)
    clipped_s, clipped_a = clipped
    s_true = (a_sig + b_sig).astype(np.float32)
    a_true = a_sig.astype(np.float32)
    b_true = b_sig.astype(np.float32)
    s_true[clipped_s] = np.nan
    a_true[clipped_a] = np.nan
    b_true[clipped_s | clipped_a] = np.nan
    truth = {
        "A": a_true, "B": b_true, "S": s_true, "row_bias": row_bias,
        "split": split.astype(np.float32), "vignetting": vignetting.astype(np.float32),
        "clipped_S": clipped_s, "clipped_A": clipped_a,
        "geometry": {"rows": rows, "cols": cols, "top": top, "left": left, "cfa": cfa,
                     "active_area": [top, left, height, width],
                     "masked_areas": [[0, 0, height, left], [0, left, top, width]]},
        "params": {"seed": seed, "scene": scene, "black": list(black),
                   "bias_amplitude": bias_amplitude, "white_level": white_level,
                   "signal": signal, "noise": noise},
    }
    return raw, truth


def _radiance(rng: np.random.Generator, scene: str, rows: int, cols: int) -> np.ndarray:
    """Scene radiance (rows, cols), 1 = the white target."""
    if scene == "white":
        return np.ones((rows, cols))
    if scene != "chart":
        raise ValueError(f"scene must be 'chart' or 'white', got {scene!r}")
    texture = gaussian_filter(rng.standard_normal((rows, cols)), 3.0)
    radiance = 0.9 + 0.35 * texture / texture.std()
    radiance[rows // 4: rows // 2, cols // 5: cols // 3] *= 0.3  # a dark patch with edges
    for _ in range(6):  # highlights that clip S (and sometimes A)
        r0, c0 = rng.integers(4, rows - 8), rng.integers(4, cols - 8)
        radiance[r0:r0 + 4, c0:c0 + 4] = 3.2
    return np.clip(radiance, 0.05, None)


def _frames(rng: np.random.Generator, signals: tuple[np.ndarray, np.ndarray],
            colour: np.ndarray, *, black: tuple[int, int], top: int, left: int,
            bias_amplitude: float, white_level: int, noise: float):
    """The raw frames (2, top + rows, left + cols) uint16 of the signals S and A: a per-row,
    per-colour bias over the whole raw (over-scan included), read noise, clipping. Also the
    bias (2, height, column phase) and the clipped masks of the active area."""
    rows, cols = signals[0].shape
    height, width = top + rows, left + cols
    row_bias = np.empty((2, height, 2))
    raw = np.empty((2, height, width), np.uint16)
    clipped = []
    for f, (sig, level) in enumerate(zip(signals, black, strict=True)):
        phase = rng.uniform(0, 2 * np.pi)
        wave = bias_amplitude * np.sin(2 * np.pi * np.arange(height) / 400.0 + phase)
        if noise == 0:  # integer bias: a noiseless capture is then exact in DN
            wave = np.round(wave)
        for p in range(2):
            offs = np.array([CFA_OFFSET[colour[r % 2, p]] for r in range(height)])
            row_bias[f, :, p] = level + wave + offs
        frame = row_bias[f][:, np.arange(width) % 2].copy()
        frame[top:, left:] += sig
        if noise > 0:
            frame += rng.normal(0.0, noise, frame.shape)
        frame = np.round(frame)
        clipped.append(frame[top:, left:] >= white_level)
        raw[f] = np.clip(frame, 0, white_level).astype(np.uint16)
    return raw, row_bias, clipped


def dng_options(truth: dict) -> dict:
    """The :func:`plenocli.io.dng.write_dng` keywords of a capture from
    :func:`dualpixel_capture`: a two-frame DNG (frames S, A) with its CFA, levels and margins."""
    geo = truth["geometry"]
    return {"cfa": geo["cfa"], "black_levels": truth["params"]["black"],
            "white_level": truth["params"]["white_level"], "active_area": geo["active_area"],
            "masked_areas": geo["masked_areas"], "frame_names": ["S", "A"],
            "model": "plenocli synthetic Canon EOS 5D Mark IV (dual pixel)"}


def _active_size(pixels: str | int | None) -> tuple[int, int]:
    if not pixels:
        return 192, 256
    try:
        rows, cols = ((int(pixels),) * 2 if isinstance(pixels, int) or str(pixels).isdigit()
                      else (int(v) for v in str(pixels).lower().split("x")))
    except ValueError as err:
        raise ValueError(f"pixels {pixels!r}: give ROWSxCOLS (e.g. 192x256) or one number") \
            from err
    if min(rows, cols) < 16:
        raise ValueError(f"pixels {pixels!r}: give at least 16 x 16 (e.g. 192x256)")
    return rows, cols


def simulate_capture_set(*, seed: int = 0, pixels: str | int | None = None,
                         noise: float = 2.0) -> Simulation:
    """``plenocli simulate dualpixel``: capture.dng, white.dng and their truth.

    ``pixels`` is the active size as ``ROWSxCOLS`` (default 192x256); full size is 4480x6720
    with Canon's margins (top 42, left 136 would break nothing: margins here are kept even).
    Truth: ``truth.json`` (parameters, geometry) and ``truth.npz`` (per-row bias, A, B, S, split,
    vignetting and clipping masks of each capture, prefixed ``capture_`` / ``white_``).
    """
    rows, cols = _active_size(pixels)
    margins = {"top": 42, "left": 136} if rows >= 2000 else {"top": 16, "left": 64}
    arrays, summary, files = {}, {}, []
    for name, scene, s in (("capture", "chart", seed), ("white", "white", seed + 1)):
        raw, truth = dualpixel_capture(seed=s, rows=rows, cols=cols, scene=scene, noise=noise,
                                       **margins)
        files.append(SimFile(f"{name}.dng", raw, "dng", dng_options(truth)))
        for key in ("A", "B", "S", "row_bias", "split", "vignetting", "clipped_S", "clipped_A"):
            arrays[f"{name}_{key}"] = truth[key]
        summary[name] = {"file": f"{name}.dng", "geometry": truth["geometry"],
                         "params": truth["params"],
                         "clipped_S_pixels": int(truth["clipped_S"].sum())}
    files.append(SimFile("truth.npz", arrays, "npz"))
    doc = {"kind": "dualpixel", "frames": ["S", "A"], "captures": summary,
           "arrays": "truth.npz (A, B, S in DN above black of the active area; row_bias "
                     "(frame, row, column phase) in DN over the full raw height)"}
    return Simulation(tuple(files), doc)
