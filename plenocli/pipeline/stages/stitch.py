"""Stage ``stitch``: a views TIFF (2 or 4 pages) -> extended-FOV panorama TIFF + JSON report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from plenocli import stitch as stitch_lib
from plenocli.cfa import shift_pattern
from plenocli.errors import InputError
from plenocli.io import tiffio
from plenocli.io.atomic import write_text
from plenocli.io.preview import write_png
from plenocli.progress import log
from plenocli.provenance import stage_record


def select_views(data: np.ndarray, meta: dict, views: str | None) -> tuple[np.ndarray, list[str]]:
    """Pages of ``data`` named in ``views`` ("A,B"; names from the metadata, or page numbers)."""
    names = list(meta.get("views") or [str(k) for k in range(data.shape[0])])
    if not views:
        return data, names
    wanted = [v.strip() for v in views.split(",") if v.strip()]
    idx = []
    for name in wanted:
        if name in names:
            idx.append(names.index(name))
        elif name.isdigit() and int(name) < data.shape[0]:
            idx.append(int(name))
        else:
            raise InputError(f"view {name!r} is not in the input (views: {','.join(names)}); "
                             "pass --views with names from that list")
    return data[idx], [names[k] for k in idx]


def bayer_to_rgb(view: np.ndarray, cfa: str) -> np.ndarray:
    """(3, rows // 2, cols // 2) half-size RGB of a Bayer view (greens averaged, NaN kept)."""
    rows, cols = (view.shape[0] // 2) * 2, (view.shape[1] // 2) * 2
    planes: dict[str, list[np.ndarray]] = {"R": [], "G": [], "B": []}
    for k, colour in enumerate(cfa.upper()):
        planes[colour].append(view[k // 2:rows:2, k % 2:cols:2].astype(np.float32))
    return np.stack([np.mean(planes[c], axis=0) for c in "RGB"])


def run(input: str, output: str, *, views: str | None = None, layout: str = "auto",
        model: str = "translation", distortion: float = 0.0, transform_in: str | None = None,
        transform_out: str | None = None, blend: str = "feather", report: str | None = None,
        preview: str | None = None) -> None:
    """Stitch the views of ``input`` into ``output``; optional report, transform and preview."""
    data, meta = tiffio.read_image(input)
    data, names = select_views(data, meta, views)
    cfa = meta.get("cfa")
    area = meta.get("active_area")
    if area:  # stitch the light-sensitive area only
        top, left, bottom, right = area
        data = data[:, top:bottom, left:right]
        cfa = shift_pattern(cfa, top, left)
    if cfa:  # Bayer views: stitch half-size RGB (registration needs whole CFA cells)
        stack = np.stack([bayer_to_rgb(v, cfa) for v in data])
    else:
        stack = data.astype(np.float32)
    transform = None
    if transform_in:
        path = Path(transform_in)
        if not path.is_file():
            raise InputError(f"{path}: no such file (the --transform-in JSON)")
        try:
            transform = json.loads(path.read_text(encoding="utf-8"))
            transform = transform.get("transform", transform)
        except (json.JSONDecodeError, UnicodeDecodeError, AttributeError) as err:
            raise InputError(f"{path}: not a JSON stitch transform ({err}); save one with "
                             "--transform-out") from err
    panorama, rep = stitch_lib.stitch(stack, layout=layout, model=model,
                                      distortion_k1=distortion, transform=transform, blend=blend)
    params = dict(views=views, layout=layout, model=model, distortion=distortion,
                  transform_in=transform_in, blend=blend)
    record = stage_record("stitch", params, {"input": input, "transform_in": transform_in})
    rep.update(input_views=names, bayer_half_size=bool(cfa))
    protect = tuple(p for p in (input, transform_in) if p)
    pano = panorama if panorama.ndim == 3 else panorama[np.newaxis]
    page_names = ["R", "G", "B"] if cfa else (["panorama"] if pano.shape[0] == 1
                                               else [f"C{c}" for c in range(pano.shape[0])])
    out_meta = tiffio.derived_meta(meta, record, views=page_names, cfa=None, active_area=None,
                                   masked_areas=None, origin=None,
                                   stitch={k: rep[k] for k in ("model", "layout", "shifts_px",
                                                               "residual_px", "origin_px")})
    tiffio.write_image(output, pano.astype(np.float32), out_meta, protect=protect)
    if report:
        write_text(report, json.dumps(_plain({**rep, "provenance": record}), indent=2,
                                      allow_nan=False), protect=protect)
    if transform_out:
        write_text(transform_out, json.dumps(_plain({"transform": rep["transform"],
                                                     "provenance": record}), indent=2),
                   protect=protect)
    if preview:
        image = np.moveaxis(pano, 0, -1) if pano.shape[0] == 3 else pano[0]
        write_png(preview, image, protect=protect)
    log.info("stitch: %s -> %s (%s, layout %s, %d x %d px, residual %s px)", input, output,
             model, rep["layout"], pano.shape[2], pano.shape[1],
             "n/a" if rep["residual_px"] is None else f"{rep['residual_px']:.3f}")


def _plain(value):
    """JSON-safe: NaN/inf -> null, numpy -> Python."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (np.floating, float)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value
