"""Provenance: every output records the plenocli version, the stage, its parameters and the
sha256 of its inputs, so a result can be traced and reproduced."""

from __future__ import annotations

import contextvars
import datetime as _dt
import hashlib
import os
import threading
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import numpy as np

from plenocli import __version__

_HASHES: dict[tuple, str] = {}
_AHEAD: dict[tuple, Future] = {}  # hashes being computed beside the stage's work
# The fully resolved parameters of the stage being run, set by its edge (Stage.guard), so that
# every record holds all of them, defaults included, whatever subset a stage passes.
RESOLVED: contextvars.ContextVar[dict | None] = contextvars.ContextVar("plenocli_resolved",
                                                                      default=None)
# and the parameters that have no effect in this run (depth's --max-disparity on lenslet
# frames): not recorded, as the run did not use them
UNUSED: contextvars.ContextVar[frozenset] = contextvars.ContextVar("plenocli_unused",
                                                                   default=frozenset())


def sha256_file(path: str | os.PathLike, *, chunk: int = 1 << 22) -> str:
    """Hex sha256 of a file's bytes.

    Remembered per process by (device, inode, size, mtime, ctime): a shared input (the white
    image of a batch) is hashed once, and any change to the file gives a new key (the change
    time too, which no copy that keeps times can set back).
    """
    key = _key(path)
    if key not in _HASHES:
        ahead = _AHEAD.pop(key, None)
        _HASHES[key] = ahead.result() if ahead is not None else _digest(path, chunk)
    return _HASHES[key]


def hash_ahead(paths) -> None:
    """Start hashing the files among ``paths`` in a background thread, so the stage's record
    finds their sha256 ready (hashlib releases the GIL: a 380 MB capture costs 0.5-1.7 s to hash,
    now beside the work that reads it). A daemon thread: a refused stage does not wait for it."""
    keys = {}
    for p in paths:
        try:
            key = _key(p)
        except OSError:
            continue  # the stage says what is wrong with it
        if key not in _HASHES and key not in _AHEAD and os.path.isfile(p):
            keys[key] = p
    if not keys:
        return
    futures = {key: Future() for key in keys}
    _AHEAD.update(futures)

    def work() -> None:
        for key, p in keys.items():
            try:
                futures[key].set_result(_digest(p, 1 << 22))
            except BaseException as err:  # given to the stage that asks for the hash
                futures[key].set_exception(err)

    threading.Thread(target=work, name="plenocli-hash", daemon=True).start()


def _key(path) -> tuple:
    st = os.stat(path)
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)


def _digest(path, chunk: int) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def json_safe(value: Any) -> Any:
    """Plain JSON/YAML values: paths as strings, tuples and arrays as lists, numpy scalars as
    Python numbers, NaN and infinities as None (JSON has no NaN)."""
    if isinstance(value, os.PathLike):
        return str(value)
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def stage_record(stage: str, parameters: dict, inputs: dict[str, Any]) -> dict:
    """The provenance record of one stage run.

    ``inputs`` maps a role (``input``, ``white``, ...) to a path or a list of paths; each file is
    hashed and recorded as given and as an absolute path. Parameters that are paths are kept as
    given (the hashes identify the content).
    Inside a stage run the edge's fully resolved parameters are recorded, with ``parameters``
    on top (a stage may add derived values), but for those without effect in this run.
    """
    resolved = RESOLVED.get()
    if resolved is not None:
        parameters = {**resolved, **parameters}
    unused = UNUSED.get()
    parameters = {k: v for k, v in parameters.items() if k not in unused}
    hashed: list[dict] = []
    for role, value in inputs.items():
        paths = value if isinstance(value, (list, tuple)) else [value]
        for p in paths:
            if p is None:
                continue
            # the path as given (relative to where the command ran) and absolute, so that
            # the history can find its inputs from another folder
            hashed.append({"role": role, "path": str(p), "absolute_path": os.path.abspath(p),
                           "sha256": sha256_file(p), "name": Path(p).name})
    return {
        "software": "plenocli",
        "version": __version__,
        "stage": stage,
        "parameters": json_safe(parameters),
        "inputs": hashed,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }


def parameters_of(record: dict | None) -> dict | None:
    """The parameters stored in a provenance record (None when there is no record)."""
    return None if not record else record.get("parameters")


def processing_of(meta: dict) -> list[str]:
    """The stages that made a file, oldest first (its history, then its own record), named as
    what changes its light levels: the stage, and for a refocused view its pupil mask width
    (``refocus(mask_width=2)``). [] for a file without a plenocli record."""
    records = [*(meta.get("history") or []), meta.get("provenance")]
    steps = []
    for record in records:
        if not isinstance(record, dict) or not isinstance(record.get("stage"), str):
            continue
        step = record["stage"]
        params = record.get("parameters") if isinstance(record.get("parameters"), dict) else {}
        if step == "refocus" and params.get("view", "full") != "full":
            step = f"refocus(mask_width={params.get('mask_width')})"
        steps.append(step)
    return steps
