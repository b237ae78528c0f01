"""Output records: how each output of a stage run was made, in a small side file beside it.

Every stage run (from the shell, a config, a batch or make) writes, landing together with its
outputs, one JSON record per output: ``.NAME.plenocli.json`` beside NAME (beside the folder, for
a folder output). A record holds the stage, the output's role (``output``, ``preview``, ...),
the stage's fully resolved parameters other than file paths, the size, modification time and
sha256 of each input by role when the run started, and those of the output as written. Whatever
the output's format (TIFF, JPEG, PNG, a folder), the record can be read, so the make-style
runner trusts an output only when its record is there and matches: a changed parameter, another
input file or an input changed in any way since (newer or older), an output edited or replaced
by another program, or an output given another role makes the step run again.

Paths themselves are not recorded: a project folder moved or copied with its times kept (``mv``,
``cp -p``, ``rsync -a``) stays up to date, since what identifies an input is its role, size,
time and content, and a record travels with its output. Size and time alone would not do:
another frame of the same camera copied over an input with its time kept (a card's or an
archive's whole-second times) has both.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from typing import Any

from plenocli import __version__
from plenocli.errors import InputError
from plenocli.io.atomic import check_file_kind, short_name, write_text, written_path
from plenocli.io.yamlfile import read_json
from plenocli.model.provenance import json_safe, sha256_file
from plenocli.pipeline.validators import RECORD_SUFFIX

SUFFIX = RECORD_SUFFIX
Roles = dict[str, list[Path]]  # a stage's file parameters by role, each a list of paths


def record_path(output: str | os.PathLike) -> Path:
    """Where the record of ``output`` lives (``.`` or ``dir/..`` named by the folder's name)."""
    output = Path(os.path.abspath(output))
    return output.parent / f".{short_name(output.name)}{SUFFIX}"


def check_record_paths(outputs: list[Path], inputs: list[Path]) -> None:
    """Before any work: the record each output gets beside it must be writable as a file, and
    not another output or an input (the run would succeed, then fail to land). A record is
    plenocli's own hidden file: a symbolic link there is replaced, never written through
    (:func:`write_records`), and one that leads to an input or an output is refused all the
    same (a user's link onto the photograph being read says something is wrong)."""
    others = [Path(os.path.abspath(p)) for p in [*outputs, *inputs]]
    for output in outputs:
        record = record_path(output)
        if record.is_dir() and not record.is_symlink():
            raise InputError(f"{record}, where plenocli records how {output} was made, is a "
                             "folder; remove it or choose another output name")
        if record.is_symlink() and any(_same_file(record, p) for p in others):
            raise InputError(f"{record}, where plenocli records how {output} was made, is a "
                             f"link to {os.readlink(record)}, a file of this command; remove "
                             "the link")
        if record in others or any(_same_file(record, p) for p in others):
            raise InputError(f"{record} is the record plenocli writes beside {output}; choose "
                             "another name for it")
        check_file_kind(record, follow=False)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def file_state(path: str | os.PathLike, *, hashed: bool = True) -> list | None:
    """[size, mtime in ns, sha256] of a file (None when it is not there; no sha256 for a
    folder, nor when not ``hashed``). Size and time alone do not tell two files apart: frames of
    one camera have one size, and cards, archives and ``touch -r`` give them the same
    whole-second time."""
    try:
        st = os.stat(path)
        digest = sha256_file(path) if hashed and stat.S_ISREG(st.st_mode) else None
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns, digest]


def input_states(inputs: Roles, *, hashed: bool = True) -> dict[str, list]:
    """The state of each input by role, taken before a stage reads them (a change while it
    runs then shows as a change later); without the sha256 when not ``hashed`` (see
    :func:`with_digests`)."""
    return {role: [file_state(p, hashed=hashed) for p in paths]
            for role, paths in inputs.items() if paths}


def with_digests(states: dict[str, list], inputs: Roles) -> dict[str, list]:
    """``states`` taken unhashed, with each file's sha256 added: computed by then beside the
    stage's work (:func:`plenocli.model.provenance.hash_ahead`), not before it."""
    return {role: [state if state is None or not os.path.isfile(path)
                   else [state[0], state[1], sha256_file(path)]
                   for state, path in zip(found, inputs[role], strict=True)]
            for role, found in states.items()}


def values(params: dict[str, Any], paths: Roles) -> dict[str, Any]:
    """The parameters that are not file paths, as JSON values (what a record compares)."""
    return as_json({k: v for k, v in params.items() if k not in paths})


def as_json(value: Any) -> Any:
    """``value`` as a record holds it (tuples as lists, numpy numbers as Python's)."""
    return json.loads(json.dumps(json_safe(value), default=str))


def write_records(stage: str, params: dict[str, Any], inputs: Roles, outputs: Roles,
                  states: dict[str, list], landed: list[tuple[Path, Path]]) -> None:
    """Write the record of every output this run wrote: a file among the ``landed``
    (temporary, destination) pairs, or a folder holding some of them. ``states``: the inputs'
    :func:`input_states` when the run started."""
    recorded = values(params, {**inputs, **outputs})
    for role, paths in outputs.items():
        for output in paths:
            # a link's target is what landed; a folder's files landed through its link too
            target = os.path.realpath(written_path(output))
            files = {}
            for tmp, dest in landed:
                full = os.path.realpath(dest)
                if full == target or full.startswith(target + os.sep):
                    files[os.path.relpath(full, target)] = file_state(tmp)
            if not files:
                continue
            doc = {"software": "plenocli", "version": __version__, "stage": stage,
                   "role": role, "parameters": recorded, "inputs": states, "output": files}
            write_text(record_path(output), json.dumps(doc, indent=1, allow_nan=False) + "\n",
                       through_links=False)


def read_record(output: str | os.PathLike) -> dict | None:
    """The record of ``output``, or None when there is none or it cannot be read."""
    try:
        doc = read_json(record_path(output))
    except (OSError, ValueError):
        return None
    shape = {"stage": str, "role": str, "parameters": dict, "inputs": dict, "output": dict}
    if not isinstance(doc, dict) or any(not isinstance(doc.get(k), t) for k, t in shape.items()):
        return None
    return doc


def remove_replaced(folder: Path, earlier: dict | None, landed: list[tuple[Path, Path]]) -> list:
    """After a stage filled ``folder`` again: remove the files its ``earlier`` record lists that
    this run did not write and that are as that run left them (size and time), so the folder
    holds one run's set, not two mixed (a simulation of another kind beside the new truth).
    Files of anyone else, or changed since, are kept. Returns the names removed."""
    if earlier is None:
        return []
    top = os.path.abspath(folder)
    written = {os.path.relpath(os.path.abspath(dest), top) for _, dest in landed}
    removed = []
    for rel, state in earlier["output"].items():
        path = Path(top) / rel
        if rel in written or rel == "." or os.path.isabs(rel) or rel.startswith(".."):
            continue
        now = file_state(path, hashed=False)
        if now is not None and isinstance(state, list) and now[:2] == state[:2]:
            path.unlink(missing_ok=True)
            removed.append(rel)
    return removed


def why_stale(stage: str, params: dict[str, Any], inputs: Roles,
              outputs: Roles, resolved=None) -> str | None:
    """Why the existing ``outputs`` cannot stand for a run of ``stage`` with ``params`` and
    ``inputs`` now (None when every one has a record that matches). ``resolved(name, value)``:
    a recorded value as the parameter's validator resolves it now, so that a record written
    before a value was resolved (``'2 : 6 : 0.5'``) compares as the value it stands for."""
    current = values(params, {**inputs, **outputs})
    states = input_states(inputs)
    for role, paths in outputs.items():
        for output in paths:
            reason = _mismatch(stage, role, Path(output), current, states, inputs,
                               resolved or (lambda _name, value: value))
            if reason:
                return reason
    return None


def _shown(value) -> str:
    """A parameter's value as the user wrote it: 4, 2:6:0.5, [1, 2], unset (no Python repr)."""
    if value is None:
        return "unset"
    return value if isinstance(value, str) else json.dumps(value)


def _mismatch(stage: str, role: str, output: Path, current: dict, states: dict,
              inputs: Roles, resolved) -> str | None:
    name = output.name
    record = read_record(output)
    if record is None:
        return f"no record of how {name} was made"
    if (record["stage"], record["role"]) != (stage, role):
        return f"{name} was made as {record['stage']} {record['role']}"
    recorded = {key: as_json(resolved(key, value))
                for key, value in record["parameters"].items()}
    for key in dict.fromkeys([*current, *recorded]):
        if recorded.get(key) != current.get(key):
            return (f"parameter {key} changed ({_shown(recorded.get(key))} -> "
                    f"{_shown(current.get(key))})")
    for rel, state in record["output"].items():
        if file_state(output / rel if rel != "." else output) != state:
            return f"{name} changed since it was made"
    for key in dict.fromkeys([*states, *record["inputs"]]):
        now, then = states.get(key, []), record["inputs"].get(key, [])
        if now != then:
            changed = [p.name for p, a, b in zip(inputs.get(key, []), now, then, strict=False)
                       if a != b]
            if changed and len(now) == len(then):
                return (f"{changed[0]} is not the {key} file {name} was made from (size, "
                        "time or content)")
            return f"the {key} files are not those {name} was made from"
    return None
