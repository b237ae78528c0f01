"""Stage ``refocus``: frames TIFF + lens grid -> refocused image(s) by Lanczos splatting (Eq. 3)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from plenocli import refocus as rf
from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.io.gridfile import read_grid
from plenocli.io.preview import write_png
from plenocli.model.cfa import shift_pattern
from plenocli.model.lensgrid import LensGrid
from plenocli.model.provenance import stage_record
from plenocli.progress import log, shown


def load_grid(path: str, meta: dict, shape: tuple[int, int]) -> LensGrid:
    """Read a lens grid; a RayCalibData XML is placed on the frames' active area (its offsets
    are measured from the image centre)."""
    if Path(path).suffix.lower() != ".xml":
        return read_grid(path)
    top, left, bottom, right = (int(v) for v in (meta.get("active_area")
                                                 or (0, 0, *shape)))
    return read_grid(path, image_shape=(bottom - top, right - left))


def frame_region(shape: tuple[int, int], meta: dict, grid: LensGrid,
                 frames_path: str, grid_path: str) -> tuple[int, int, int, int, LensGrid]:
    """The part of the frames the grid describes, and the grid in that crop's coordinates.

    Returns (r0, c0, r1, c1, grid_in_crop). Frames carry their sensor ``origin``; the grid its
    ``sensor_origin`` and ``image_shape`` (the white image it was calibrated on). The grid's
    image must lie inside the frames; a grid without a size covers the frames' active area.
    """
    rows, cols = shape
    fo_r, fo_c = (int(v) for v in (meta.get("origin") or (0, 0)))
    go_r, go_c = (int(v) for v in grid.sensor_origin)
    if grid.image_shape is not None:
        gr, gc = (int(v) for v in grid.image_shape)
        r0, c0 = go_r - fo_r, go_c - fo_c
        r1, c1 = r0 + gr, c0 + gc
        if r0 < 0 or c0 < 0 or r1 > rows or c1 > cols:
            raise InputError(
                f"{grid_path} was calibrated on a {gc} x {gr} image at sensor origin "
                f"({go_r}, {go_c}) but {frames_path} is {cols} x {rows} at ({fo_r}, {fo_c}); "
                "use a grid calibrated on a white image of the same camera and crop")
    else:
        r0, c0, r1, c1 = (int(v) for v in (meta.get("active_area") or (0, 0, rows, cols)))
    dx, dy = fo_c + c0 - go_c, fo_r + r0 - go_r
    return r0, c0, r1, c1, (rf.shift_grid(grid, dx, dy) if (dx or dy) else grid)


def run(input: str, output: str, *, grid: str, s: float = 0.2, g: str | float = "4",
        view: str = "full", mask_width: float = 2.0, kernel: str = "lanczos3",
        radius: float | None = None, min_weight: float = 0.25,
        preview: str | None = None) -> None:
    """Refocus every page of ``input`` at each g; one output page per (g, channel)."""
    try:
        g_values = rf.parse_g(g)
    except ValueError as err:
        raise ConfigError(f"--g: {err}") from err
    try:  # refuse bad values before any file is read
        rf.check_options(s=s, g=g_values[0], view=view, mask_width=mask_width, kernel=kernel,
                         radius=radius, cfa=None, min_weight=min_weight)
    except ValueError as err:
        raise ConfigError(f"refocus: {err}") from err
    data, meta = tiffio.read_image(input)
    lens_grid = load_grid(grid, meta, data.shape[1:])
    r0, c0, r1, c1, crop_grid = frame_region(data.shape[1:], meta, lens_grid, input, grid)
    try:
        rf.check_output_size((r1 - r0, c1 - c0), s,
                             pages=len(g_values) * data.shape[0] * (3 if meta.get("cfa") else 1))
    except ValueError as err:
        raise ConfigError(f"refocus: {err}") from err
    cfa = shift_pattern(meta.get("cfa"), r0, c0)
    pages = list(meta.get("views") or [f"view{k}" for k in range(data.shape[0])])
    sweep = len(g_values) > 1
    out_pages, names, scores = [], [], []
    period = s * lens_grid.pitch_px
    for g_value in g_values:
        per_g = []
        for page, name in zip(data, pages, strict=True):
            image, _ = rf.refocus(page[r0:r1, c0:c1], crop_grid, s=s, g=g_value, view=view,
                                  mask_width=mask_width, kernel=kernel, radius=radius,
                                  cfa=cfa, min_weight=min_weight)
            channels = image if cfa else image[np.newaxis]
            labels = list(rf.CHANNELS) if cfa else [name]
            if cfa and len(pages) > 1:
                labels = [f"{name}.{c}" for c in rf.CHANNELS]
            for chan, label in zip(channels, labels, strict=True):
                per_g.append(chan)
                names.append(f"{label}@g{g_value:g}" if sweep else label)
        score = rf.sharpness(np.stack(per_g), lens_period_px=period)
        scores.append({"g": g_value, "sharpness": score})
        log.info("refocus: g = %g  sharpness %.5g", g_value, score)
        out_pages.extend(per_g)
    finite = [sc for sc in scores if np.isfinite(sc["sharpness"])]
    best = max(finite, key=lambda sc: sc["sharpness"])["g"] if finite else None
    params = dict(grid=grid, s=s, g=g, view=view, mask_width=mask_width, kernel=kernel,
                  radius=radius, min_weight=min_weight)
    record = stage_record("refocus", params, {"input": input, "grid": grid})
    stack = np.stack(out_pages).astype(np.float32)
    origin = [int(v) for v in (meta.get("origin") or (0, 0))]
    covered = float(np.isfinite(stack).mean())
    out_meta = tiffio.derived_meta(
        meta, record, views=names, cfa=None, origin=None, black_level=None, white_level=None,
        active_area=[0, 0, stack.shape[1], stack.shape[2]], masked_areas=[],
        refocus={"equation": "(X, Y) = s * (g * ((x, y) - c_ij) + c_ij)", "s": s,
                 "g": g_values, "view": view, "mask_width": mask_width, "kernel": kernel,
                 "radius": radius, "crop_sensor_origin": [origin[0] + r0, origin[1] + c0],
                 "covered_fraction": covered},
        sharpness={"measure": "mean(Lap(I_s)^2) / var(I_s), I_s = Gaussian(sigma = s * pitch / 2)",
                   "lens_period_px": period, "scores": scores, "best_g": best})
    tiffio.write_image(output, stack, out_meta, protect=(input, grid))
    log.info("refocus: %s -> %s (%d page(s) of %d x %d, view %s, %.1f %% covered%s)",
             shown(input), shown(output), stack.shape[0], stack.shape[2], stack.shape[1], view,
             100 * covered,
             f", sharpest g = {best:g}" if sweep and best is not None else "")
    if preview:
        per = len(out_pages) // len(g_values)
        k = g_values.index(best) if best is not None else 0
        chunk = stack[k * per:(k + 1) * per]
        rgb = cfa or [n.split("@")[0] for n in names[:per]] == list(rf.CHANNELS)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns stay NaN
            picture = np.dstack(chunk) if rgb else np.nanmean(chunk, axis=0)
        write_png(preview, picture, protect=(input, grid))
