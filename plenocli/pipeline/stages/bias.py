"""Stage ``bias``: frames with over-scan -> bias-corrected views of the active area.

Each frame is corrected with its own over-scan. For a dual-pixel capture (frames named S and A)
the output views are A, B = S - A and S; values derived from clipped raw pixels are NaN.
"""

from __future__ import annotations

import numpy as np

from plenocli.dualpixel import capture_views
from plenocli.errors import InputError
from plenocli.io import tiffio
from plenocli.io.preview import write_png
from plenocli.model.cfa import shift_pattern
from plenocli.model.provenance import stage_record
from plenocli.progress import log, shown


def run(input: str, output: str, *, overscan: str = "auto", smooth: int = 0, guard: int = 2,
        crop: str | None = None, preview: str | None = None) -> None:
    """Bias-correct the frames of ``input`` (from decode) and crop them to the active area."""
    frames, meta = tiffio.read_image(input)
    if "active_area" not in meta:
        raise InputError(f"{input}: not a decoded frames file (no active_area in its metadata); "
                         "run plenocli decode first")
    made = (meta.get("provenance") or {}).get("stage")
    if made != "decode":
        raise InputError(f"{input}: " + (f"a `plenocli {made}` output" if made else
                                         "no plenocli record") +
                         "; bias needs the output of plenocli decode")
    cfa = meta.get("cfa")
    try:
        corrected = capture_views(
            frames, names=list(meta["views"]), active_area=meta["active_area"],
            masked_areas=meta.get("masked_areas"), black_level=meta["black_level"],
            white_level=tiffio.white_levels(meta, len(frames)), cfa=cfa, overscan=overscan,
            smooth=smooth, guard=guard)
    except ValueError as err:
        raise InputError(f"{input}: {err}") from err
    del frames
    views, names = corrected.views, list(corrected.names)
    levels = [_summary(info, name)
              for info, name in zip(corrected.levels, meta["views"], strict=True)]
    top, left = meta["active_area"][:2]
    row0, col0 = 0, 0
    if crop:
        views, row0, col0 = _central_crop(views, crop, even=bool(cfa))
    origin0 = meta.get("origin", [0, 0])
    origin = [origin0[0] + top + row0, origin0[1] + left + col0]
    # where the sensor's active area starts: an ideal N x N sensor's micro-image (0, 0), which
    # sai needs to know once --crop has moved the origin into the micro-images
    active_origin = [origin0[0] + top, origin0[1] + left]  # bias reads decode's frames only
    new_cfa = shift_pattern(cfa, top + row0, left + col0)
    params = dict(overscan=overscan, smooth=smooth, guard=guard, crop=crop)
    record = stage_record("bias", params, {"input": input})
    rows, cols = views.shape[1:]
    out_meta = tiffio.derived_meta(meta, record, views=names, cfa=new_cfa, origin=origin,
                                   active_origin=active_origin,
                                   active_area=[0, 0, rows, cols], masked_areas=[],
                                   black_level=[[0.0] * 4] * len(names),
                                   white_level=list(corrected.white_level),
                                   bias_levels=levels,
                                   clipped_pixels=int(np.isnan(views).any(axis=0).sum()))
    tiffio.write_image(output, views, out_meta, protect=(input,))
    log.info("bias: %s -> %s (%s, views %s, %d x %d, %d clipped pixels masked)",
             shown(input), shown(output), levels[0]["mode"], ",".join(names), cols, rows,
             out_meta["clipped_pixels"])
    if preview:
        write_png(preview, views[:2], cfa=new_cfa, protect=(input,), colour=meta.get("colour"))


def _summary(info: dict, name: str) -> dict:
    """Levels in the metadata: per-colour-position means, and per-row values (compact)."""
    out = {"frame": name, "mode": info["mode"]}
    if "row_levels" in info:
        rows = info["row_levels"]
        out["row_levels_mean"] = [round(float(v), 3) for v in rows.mean(axis=0)]
        out["row_levels"] = np.round(rows, 3).tolist()
    if "column_levels" in info:
        out["column_levels_mean"] = [round(float(v), 3) for v in info["column_levels"].mean(axis=1)]
    if "black_level" in info:
        out["black_level"] = info["black_level"]
    return out


def _central_crop(views: np.ndarray, crop: str, *, even: bool):
    try:
        rows, cols = (int(v) for v in crop.lower().split("x"))
    except ValueError as err:
        raise InputError(f"crop {crop!r} is not ROWSxCOLS (e.g. 2000x2000)") from err
    height, width = views.shape[1:]
    if not (0 < rows <= height and 0 < cols <= width):
        raise InputError(f"crop {crop} does not fit the {height}x{width} active area")
    if even and min(rows, cols) < 2:
        raise InputError(f"crop {crop} is smaller than one 2 x 2 CFA cell; crop at least 2x2 "
                         "(a few hundred pixels a side to see anything)")
    r0, c0 = (height - rows) // 2, (width - cols) // 2
    if even:  # keep the CFA phase
        r0, c0 = r0 - r0 % 2, c0 - c0 % 2
    return views[:, r0:r0 + rows, c0:c0 + cols].copy(), r0, c0
