"""A saved stitch transform (``--transform-out`` / ``--transform-in``): JSON ``{"transform":
{model, layout, view_shape, distortion_k1, rig, views, view_to_reference}, "provenance"}``.
Read, it is checked against the views it is given by name (distinct names, in the order of
these views); the stitch then checks it against the views themselves (model, layout, size,
rig, matrices, overlaps: :func:`plenocli.stitch.registration.check_transform`)."""

from __future__ import annotations

import json
import math
from pathlib import Path

from plenocli.errors import InputError
from plenocli.io.atomic import write_text
from plenocli.io.yamlfile import read_json, read_side_file
from plenocli.model.provenance import json_safe


def read_transform(path: str | Path, names: list[str], *, held: list[str] | None = None) -> dict:
    """A transform saved by ``--transform-out`` (the JSON, or its ``transform`` key), refused
    unless it is a mapping, and, when it names its views, unless they are distinct names in the
    order of ``names`` (views named after other files are not compared)."""
    file = Path(path)
    data = read_side_file(file, "JSON stitch transform", read=read_json,
                          hint="save one with --transform-out")
    transform = data.get("transform", data) if isinstance(data, dict) else None
    if not isinstance(transform, dict):
        raise InputError(f"{file}: not a JSON stitch transform (no mapping); save one with "
                         "--transform-out")
    _check_matrices(file, transform.get("view_to_reference"))
    _check_layout(file, transform)
    saved = transform.get("views")
    if saved is not None:
        if not isinstance(saved, list) or not all(isinstance(n, str) for n in saved) \
                or len(set(saved)) != len(saved):
            raise InputError(f"{file}: the transform's views must be distinct names, got "
                             f"{saved!r}; save one with --transform-out")
        if saved != names and set(saved) & set(names):  # other names: other files, can't tell
            raise InputError(f"{file}: the transform was made for views {','.join(saved)}, "
                             f"these are {','.join(names)}; {views_remedy(saved, held)}")
    return transform


def views_remedy(saved: list, held: list[str] | None) -> str:
    """What to do about a transform made for views ``saved``: pick them with --views when the
    input holds them all (``held``: its views; None: not known), else register again."""
    again = "register them again (without --transform-in)"
    missing = [str(n) for n in saved if held is not None and n not in held]
    if missing:
        return f"the input holds no view {missing[0]}: {again}"
    return f"pass --views {','.join(map(str, saved))} or {again}"


def _check_layout(file: Path, transform: dict) -> None:
    """A pair's layout (1x2: side by side, 2x1: one above the other) must be the direction
    its matrices move the second view: an edited layout was refused as "a false match"."""
    layout, matrices = transform.get("layout"), transform["view_to_reference"]
    if layout not in ("1x2", "2x1") or len(matrices) != 2:
        return
    dx = matrices[1][0][2] - matrices[0][0][2]
    dy = matrices[1][1][2] - matrices[0][1][2]
    beside = abs(dx) >= abs(dy)
    if beside != (layout == "1x2"):
        raise InputError(f"{file}: the transform's layout {layout} contradicts its matrices, "
                         f"which put the second view {dx:.0f}, {dy:.0f} px from the first "
                         f"({'side by side, 1x2' if beside else 'one above the other, 2x1'}); "
                         "save one with --transform-out")


def _check_matrices(file: Path, matrices) -> None:
    """``view_to_reference``: a list of 3 x 3 matrices of finite numbers, one per view; the
    one that is not is named."""
    if not isinstance(matrices, list):
        raise InputError(f"{file}: the transform's view_to_reference is {type(matrices).__name__}"
                         ", not a list of 3 x 3 matrices; save one with --transform-out")
    for k, matrix in enumerate(matrices):
        rows = matrix if isinstance(matrix, list) and len(matrix) == 3 else None
        if rows is None or not all(
                isinstance(row, list) and len(row) == 3
                and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                        and math.isfinite(v) for v in row) for row in rows):
            raise InputError(f"{file}: view {k}'s matrix in view_to_reference is not 3 x 3 "
                             "finite numbers; the file was edited or damaged: save one with "
                             "--transform-out")


def write_transform(path: str | Path, transform: dict, names: list[str], record: dict, *,
                    protect: tuple = ()) -> None:
    """The transform of a stitch (its report's ``transform``) with the views' names and the
    provenance ``record``."""
    write_text(path, json.dumps(json_safe({"transform": {**transform, "views": names},
                                           "provenance": record}), indent=2), protect=protect)
