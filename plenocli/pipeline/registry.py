"""The stage registry: every stage a config can name, with its declared parameters.

A stage is a plain function ``run(**params)`` in ``plenocli.pipeline.stages.<name>`` and the
declaration of its parameters, ``PARAMS`` in ``plenocli.pipeline.schema.<name>``
(:mod:`plenocli.pipeline.params`): the command line builds its options from it, a YAML step
and ``--set`` are resolved with it, and its roles say which parameters are files the stage
reads or writes, which is what the make-style runner and the output checks need. A schema
module may also define ``check(params)``: a check across parameters (ConfigError), run on
the resolved parameters before the stage, whichever path they came from; and
``shared_inputs(params)``: the pairs of input roles that may name one file (any other file
given twice among the inputs is refused).
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import os
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import ModuleType
from typing import Any

from plenocli.errors import ConfigError, InputError, not_a_file
from plenocli.io.atomic import check_outputs, outputs_together
from plenocli.io.folderlock import folders_locked
from plenocli.model.provenance import RESOLVED, UNUSED, hash_ahead
from plenocli.pipeline import records
from plenocli.pipeline.kinds import check_kinds
from plenocli.pipeline.params import Param, convert, names_by_role, resolve, unused_in
from plenocli.progress import log

# every stage, in pipeline order; each has stages/<name>.py and schema/<name>.py
NAMES = ("decode", "bias", "flat", "calibrate", "refocus", "depth", "sai", "crosstalk", "unmix",
         "stitch", "develop", "optics", "simulate")


@dataclass(frozen=True)
class Stage:
    name: str

    @cached_property
    def schema(self) -> ModuleType:
        """The stage's declaration module (light: no pixels, no click)."""
        return importlib.import_module(f"plenocli.pipeline.schema.{self.name}")

    @property
    def params(self) -> tuple[Param, ...]:
        return self.schema.PARAMS

    @property
    def inputs(self) -> tuple[str, ...]:
        return names_by_role(self.params, "input")

    @property
    def outputs(self) -> tuple[str, ...]:
        return names_by_role(self.params, "output", "folder")

    @property
    def folder_outputs(self) -> tuple[str, ...]:
        return names_by_role(self.params, "folder")

    @property
    def run(self):
        """The stage function ``run(**params)``."""
        return importlib.import_module(f"plenocli.pipeline.stages.{self.name}").run

    def parameters(self) -> dict[str, Any]:
        """Parameter names and defaults (``inspect.Parameter.empty`` when required)."""
        return {p.name: inspect.Parameter.empty if p.required else p.unset for p in self.params}

    def resolve(self, values: dict[str, Any]) -> dict[str, Any]:
        """Every parameter, converted and checked by its declared validator (ConfigError);
        ``values``: those a YAML step gives."""
        params = resolve(self.params, values)
        self.check(params, frozenset(values))
        return params

    def check(self, params: dict[str, Any], given: Collection[str]) -> None:
        """The schema's check across parameters, if it has one (ConfigError). ``given``: the
        names of the parameters the user gave (the rest hold their defaults)."""
        check = getattr(self.schema, "check", None)
        if check is not None:
            check(params, given)

    def paths(self, params: dict[str, Any], roles: tuple[str, ...]) -> list[Path]:
        """The file paths held by the parameters named in ``roles``."""
        out: list[Path] = []
        for name in roles:
            value = params.get(name)
            if value is None:
                continue
            out.extend(Path(v) for v in (value if isinstance(value, (list, tuple)) else [value]))
        return out

    @contextlib.contextmanager
    def guard(self, params: dict[str, Any]) -> Iterator[None]:
        """The edge of one stage run: outputs checked before any work, and landed together.

        Outputs must be distinct from each other and from the inputs, in writable folders;
        every file the stage writes inside the block is renamed into place only when the whole
        stage succeeded (nothing is left behind otherwise), each output with its record.
        """
        files = tuple(name for name in self.outputs if name not in self.folder_outputs)
        shared = getattr(self.schema, "shared_inputs", None)
        _check_inputs_apart(params, self.params, shared(params) if shared else ())
        for path in self.paths(params, self.inputs):  # opening a pipe would wait for a writer
            if os.path.exists(path) and not (os.path.isfile(path) or os.path.isdir(path)):
                raise not_a_file(path)
        check_kinds(self.name, self.by_role(params, self.inputs))
        check_outputs(self.paths(params, files), self.paths(params, self.inputs),
                      folders=self.paths(params, self.folder_outputs))
        records.check_record_paths(self.paths(params, self.outputs),
                                   self.paths(params, self.inputs))
        inputs, outputs = self.by_role(params, self.inputs), self.by_role(params, self.outputs)
        hash_ahead([p for paths in inputs.values() for p in paths])
        started = records.input_states(inputs, hashed=False)

        folders = self.paths(params, self.folder_outputs)
        with folders_locked(folders):
            yield from self._filled(params, inputs, outputs, started, folders)

    def _filled(self, params, inputs, outputs, started, folders) -> Iterator[None]:
        """guard's run: its outputs landed together with their records; the earlier files of
        each output folder that this run did not write again removed."""
        # a folder reached by another name (a symbolic link, or the folder a link points to)
        # has its earlier run's record under that name
        earlier = {(folder, name): records.read_record(name) for folder in folders
                   for name in dict.fromkeys([folder, Path(os.path.realpath(folder))])}
        landing: list = []

        unused, recorded = self.unused(params), self.recorded(params)

        def record(landed):
            landing.extend(landed)
            states = records.with_digests(started, inputs)
            records.write_records(self.name, recorded, inputs, outputs, states, landed)
            # a folder written through a link gets its record under its own name too, where
            # a run given that name looks for the earlier run's
            real = {role: [Path(os.path.realpath(p)) for p in outputs[role]
                           if os.path.realpath(p) != os.path.abspath(p)]
                    for role in self.folder_outputs}
            if any(real.values()):
                records.write_records(self.name, recorded, inputs, real, states, landed)

        token, hidden = RESOLVED.set(dict(params)), UNUSED.set(unused)
        try:
            with outputs_together(before_landing=record):
                yield
        finally:
            RESOLVED.reset(token)
            UNUSED.reset(hidden)
        for (folder, _), before in earlier.items():  # landed: the earlier run's files
            gone = records.remove_replaced(folder, before, landing)  # it did not write again
            if gone:
                log.info("%s: removed %s of the earlier %s run in %s", self.name,
                         ", ".join(sorted(gone)), before["stage"], folder)

    def by_role(self, params: dict[str, Any], roles: tuple[str, ...]) -> dict[str, list[Path]]:
        """The file paths of each parameter named in ``roles`` ([] when not given)."""
        return {name: self.paths(params, (name,)) for name in roles}

    def unused(self, params: dict[str, Any]) -> frozenset:
        """The parameters without effect in a run with ``params`` (the schema's check names
        them): neither the outputs' provenance nor their records hold them, so changing one
        does not make a step run again."""
        check = getattr(self.schema, "check", None)
        return unused_in(check, params) if check is not None else frozenset()

    def recorded(self, params: dict[str, Any]) -> dict[str, Any]:
        """What an output's record holds of ``params``: the declared parameters with an effect
        in this run (:meth:`unused`) and, where the schema resolves more (``recorded``:
        simulate's kind parameters, defaults included), those too."""
        kept = _without(params, self.unused(params))
        more = getattr(self.schema, "recorded", None)
        return {**kept, **more(params)} if more is not None else kept

    def why_stale(self, params: dict[str, Any]) -> str | None:
        """Why the step's existing outputs cannot stand for a run with ``params`` now (their
        records, :mod:`plenocli.pipeline.records`); None when they can."""
        return records.why_stale(self.name, self.recorded(params),
                                 self.by_role(params, self.inputs),
                                 self.by_role(params, self.outputs), self._resolved)

    def _resolved(self, name: str, value: Any) -> Any:
        """A recorded value of a declared plain parameter as its validator resolves it now
        (one an older plenocli kept as typed compares as what it stands for); any other, or
        one the validator refuses now, as recorded."""
        param = next((p for p in self.params if p.name == name and p.role == "value"), None)
        if param is None or value is None:
            return value
        try:
            return convert(param, value)
        except ConfigError:
            return value


def _without(params: dict[str, Any], names: frozenset) -> dict[str, Any]:
    return {k: v for k, v in params.items() if k not in names}


def _check_inputs_apart(params: dict[str, Any], declared: tuple[Param, ...],
                        shared: tuple[tuple[str, str], ...] = ()) -> None:
    """A file given twice among a stage's inputs, in one list (one masked white given for two
    pupil parts: measured as two captures) or in two roles (``flat in.tif --white in.tif``: an
    image flat-fielded by itself), as the same name, ``./name``, a symbolic or a hard link, is
    a mistake; only the role pairs the schema's ``shared_inputs(params)`` lists may share one."""
    seen: dict[tuple, tuple[Param, str]] = {}
    for param in declared:
        if param.role != "input" or params.get(param.name) is None:
            continue
        value = params[param.name]
        for item in value if isinstance(value, (list, tuple)) else [value]:
            key = _identity(item)
            if key not in seen:
                seen[key] = (param, item)
                continue
            first, first_item = seen[key]
            if first is param:
                raise InputError(f"{item} is given twice as {param.name.upper()}; give each "
                                 "file once")
            if (first.name, param.name) not in shared and (param.name, first.name) not in shared:
                same = "" if first_item == item else f" (the same file as {first_item})"
                raise InputError(f"{item} is given as {_shown(param)}{same} and as "
                                 f"{_shown(first)}; give each its own file")


def _identity(path: str) -> tuple:
    """What makes two names one file: device and inode when it exists (hard links too)."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return ("path", os.path.realpath(path))
    return ("inode", st.st_dev, st.st_ino)


def _shown(param: Param) -> str:
    return param.name.upper() if param.positional else param.flags[-1]


_STAGES = {name: Stage(name) for name in NAMES}


def get_stages() -> dict[str, Stage]:
    """All registered stages by name."""
    return dict(_STAGES)


def get_stage(name: str) -> Stage:
    """One stage by name (ConfigError naming the stages when unknown)."""
    stages = get_stages()
    if name not in stages:
        raise ConfigError(f"unknown stage {name!r}; stages: {', '.join(stages)}")
    return stages[name]
