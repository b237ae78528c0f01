"""Is a depth map one that ``refocus --depth`` may use on this run?

A depth map is a side file: it can come from another capture, another grid, another ``--s``
or crop, or hold values edited by hand. It is used only when its record says ``plenocli
depth`` made it of these frames (the same file, or one made from the same source: depth on the
flat-fielded frames, refocus on the biased ones), from this very grid file (the same sha256),
at this ``s`` and crop origin, and its values lie in the range that run searched
(docs/depth.md, "All-in-focus").
"""

from __future__ import annotations

import math

import numpy as np

from plenocli.depth.lenslet import check_range
from plenocli.errors import numbers


def sources(meta: dict, own_sha256: str | None = None) -> set[str]:
    """The sha256 of a file (``own_sha256``) and of every file its main input came from, back
    to the capture, as its records list them (role ``input``: not a white, grid or mixing,
    which other captures share)."""
    found = {own_sha256} - {None}
    for record in [*(meta.get("history") or []), meta.get("provenance") or {}]:
        for entry in (record.get("inputs") or []) if isinstance(record, dict) else []:
            if isinstance(entry, dict) and entry.get("role") == "input" and entry.get("sha256"):
                found.add(str(entry["sha256"]))
    return found


def depth_misfit(data: np.ndarray, meta: dict, *, grid_sha256: str, s: float,
                 sensor_origin: tuple[int, int], frames: set[str]) -> str | None:
    """None when the depth map (pages, rows, cols; ``meta`` its metadata) fits a refocus run
    of the frames whose :func:`sources` are ``frames`` on the grid with ``grid_sha256`` at
    ``s`` and crop ``sensor_origin``; else what is wrong."""
    record = meta.get("provenance") or {}
    info = meta.get("depth")
    if record.get("stage") != "depth" or not isinstance(info, dict):
        return "it is not a `plenocli depth` output (no depth record)"
    if not sources(meta) & frames:
        return ("it was made of another capture's frames (its record shares no source with "
                "these frames'); make the depth of these frames")
    grids = [i.get("sha256") for i in record.get("inputs", []) if i.get("role") == "grid"]
    if grids != [grid_sha256]:
        return "it was made with another grid (make it with the same --grid)"
    made_s = [info.get("s"), (record.get("parameters") or {}).get("s")]
    if not all(isinstance(v, (int, float)) and math.isclose(v, s, rel_tol=1e-9)
               for v in made_s):
        return f"it was made at s = {made_s[0]}, this refocus is at s = {s:g}"
    origin = info.get("crop_sensor_origin")
    if list(origin or []) != list(sensor_origin):
        return (f"it was made on the crop at sensor origin {origin}, this refocus works on "
                f"[{numbers(sensor_origin)}]")
    return _values_misfit(data, list(meta.get("views") or []), info.get("g_range"))


def _values_misfit(data: np.ndarray, names: list[str], g_range) -> str | None:
    try:
        lo, hi = check_range(tuple(g_range))
    except (TypeError, ValueError) as err:
        return f"its recorded g range {g_range!r} is not valid ({err})"
    g = data[names.index("g")]
    known = g[np.isfinite(g)]
    slack = 1e-5 * max(abs(lo), abs(hi))   # float32 pages
    outside = (known < lo - slack) | (known > hi + slack)
    if outside.any() or np.isinf(g).any():
        bad = known[outside][0] if outside.any() else g[np.isinf(g)][0]
        return f"its g holds {bad:g}, outside the range {lo:g}:{hi:g} it was searched in"
    if "confidence" in names:
        conf = data[names.index("confidence")]
        if not np.all((conf >= 0) & (conf <= 1)):
            return "its confidence holds values outside 0-1 (or NaN)"
    return None
