"""Output records: how each output of a stage run was made, in a small side file beside it.

Every stage run (from the shell, a config, a batch or make) writes, landing together with its
outputs, one JSON record per output: ``.NAME.plenocli.json`` beside NAME (beside the folder, for
a folder output). A record holds the stage, its fully resolved parameters (file paths made
absolute), the size and modification time of every input when the run started, and those
of the output as written. Whatever the output's format (TIFF, JPEG, PNG, a folder), the record
can be read, so the make-style runner trusts an output only when its record is there and
matches: a changed parameter, another input file, an input changed in any way since (newer or
older), or an output edited or replaced by another program makes the step run again.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from plenocli import __version__
from plenocli.io.atomic import short_name, write_text
from plenocli.model.provenance import json_safe

SUFFIX = ".plenocli.json"


def record_path(output: str | os.PathLike) -> Path:
    """Where the record of ``output`` lives (``.`` or ``dir/..`` named by the folder's name)."""
    output = Path(os.path.abspath(output))
    return output.parent / f".{short_name(output.name)}{SUFFIX}"


def file_state(path: str | os.PathLike) -> list[int] | None:
    """[size, mtime in ns] of a file (None when it is not there)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def real(path: str | os.PathLike) -> str:
    """An absolute path with its folders' links resolved, not its own: renaming an output onto
    a link replaces the link, so the name is what a record must follow."""
    full = os.path.abspath(path)
    return os.path.join(os.path.realpath(os.path.dirname(full)), os.path.basename(full))


def input_states(paths: Iterable[str | os.PathLike]) -> dict[str, list[int] | None]:
    """The state of each input by path, taken before a stage reads them (a change while it
    runs then shows as a change later)."""
    return {real(p): file_state(p) for p in paths}


def comparable(params: dict[str, Any], paths: Iterable[str]) -> dict[str, Any]:
    """Parameters as a record holds them: JSON values, the parameters named in ``paths`` as
    absolute paths (:func:`real`: a relative path from the shell and the config's agree)."""
    roles = set(paths)
    values = {}
    for key, value in params.items():
        if key in roles and isinstance(value, (list, tuple)):
            value = [real(v) for v in value]
        elif key in roles and value is not None:
            value = real(value)
        values[key] = value
    return json.loads(json.dumps(json_safe(values), default=str))


def write_records(stage: str, params: dict[str, Any], path_keys: Iterable[str],
                  outputs: Iterable[str | os.PathLike], inputs: dict[str, list[int] | None],
                  landed: list[tuple[Path, Path]]) -> None:
    """Write the record of every output in ``outputs`` that this run wrote (a file among the
    ``landed`` (temporary, destination) pairs, or a folder holding some of them)."""
    parameters = comparable(params, path_keys)
    for output in outputs:
        target = os.path.abspath(output)
        files = {real(dest): file_state(tmp) for tmp, dest in landed
                 if os.path.abspath(dest) == target
                 or os.path.abspath(dest).startswith(target + os.sep)}
        if not files:
            continue
        doc = {"software": "plenocli", "version": __version__, "stage": stage,
               "parameters": parameters, "inputs": inputs, "output": files}
        write_text(record_path(output), json.dumps(doc, indent=1, allow_nan=False) + "\n")


def read_record(output: str | os.PathLike) -> dict | None:
    """The record of ``output``, or None when there is none or it cannot be read."""
    try:
        doc = json.loads(record_path(output).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    shape = {"stage": str, "parameters": dict, "inputs": dict, "output": dict}
    if not isinstance(doc, dict) or any(not isinstance(doc.get(k), t) for k, t in shape.items()):
        return None
    return doc


def why_stale(stage: str, params: dict[str, Any], path_keys: Iterable[str],
              outputs: Iterable[str | os.PathLike]) -> str | None:
    """Why the existing ``outputs`` cannot stand for a run of ``stage`` with ``params`` now
    (None when every one has a record that matches)."""
    current = comparable(params, path_keys)
    for output in outputs:
        name = Path(output).name
        record = read_record(output)
        if record is None:
            return f"no record of how {name} was made"
        if record["stage"] != stage:
            return f"{name} was made by stage {record['stage']!r}"
        recorded = record["parameters"]
        for key in dict.fromkeys([*current, *recorded]):
            if recorded.get(key) != current.get(key):
                return f"parameter {key} changed ({recorded.get(key)!r} -> {current.get(key)!r})"
        for path, state in record["output"].items():
            if file_state(path) != state:
                return f"{name} changed since it was made"
        for path, state in record["inputs"].items():
            if file_state(path) != state:
                return f"{Path(path).name} changed since {name} was made"
    return None
