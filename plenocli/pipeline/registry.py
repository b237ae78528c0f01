"""The stage registry: every stage a config can name, with which parameters are files.

A stage is a plain function ``run(**params)`` in ``plenocli.pipeline.stages.<name>`` and a click
command ``plenocli.cli.<name>``. The command is the one definition of the stage's parameters
(type, range, choices, default): the shell, a YAML step and ``--set`` all go through it
(:mod:`plenocli.cli.params`); this is the one place the pipeline reaches up to the commands.
``inputs`` and ``outputs`` name the parameters that are file paths, which is what the make-style
runner and the output checks need.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from plenocli.errors import ConfigError, InputError
from plenocli.io.atomic import check_outputs, outputs_together
from plenocli.model.provenance import RESOLVED
from plenocli.pipeline import records


@dataclass(frozen=True)
class Stage:
    name: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    folder_outputs: tuple[str, ...] = ()  # outputs that are folders the stage fills

    @property
    def run(self):
        """The stage function ``run(**params)``."""
        return importlib.import_module(f"plenocli.pipeline.stages.{self.name}").run

    @property
    def command(self):
        """The click command that defines the stage's parameters."""
        return getattr(importlib.import_module(f"plenocli.cli.{self.name}"), self.name)

    def parameters(self) -> dict[str, Any]:
        """Parameter names and defaults (``inspect.Parameter.empty`` when required)."""
        from plenocli.cli.params import defaults, stage_parameters

        values = defaults(self.command)
        return {name: inspect.Parameter.empty if p.required else values.get(name)
                for name, p in stage_parameters(self.command).items()}

    def resolve(self, values: dict[str, Any]) -> dict[str, Any]:
        """Every parameter, converted and checked by the command's own types (ConfigError)."""
        from plenocli.cli.params import resolve

        return resolve(self.command, values)

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
        _check_listed_once(params, self.inputs)
        check_outputs(self.paths(params, files), self.paths(params, self.inputs),
                      folders=self.paths(params, self.folder_outputs))
        inputs, outputs = self.by_role(params, self.inputs), self.by_role(params, self.outputs)
        states = records.input_states(inputs)

        def record(landed):
            records.write_records(self.name, params, inputs, outputs, states, landed)

        token = RESOLVED.set(dict(params))
        try:
            with outputs_together(before_landing=record):
                yield
        finally:
            RESOLVED.reset(token)

    def by_role(self, params: dict[str, Any], roles: tuple[str, ...]) -> dict[str, list[Path]]:
        """The file paths of each parameter named in ``roles`` ([] when not given)."""
        return {name: self.paths(params, (name,)) for name in roles}

    def why_stale(self, params: dict[str, Any]) -> str | None:
        """Why the step's existing outputs cannot stand for a run with ``params`` now (their
        records, :mod:`plenocli.pipeline.records`); None when they can."""
        return records.why_stale(self.name, params, self.by_role(params, self.inputs),
                                 self.by_role(params, self.outputs))


def _check_listed_once(params: dict[str, Any], roles: tuple[str, ...]) -> None:
    """A file listed twice in one list of inputs (e.g. one masked white given for two pupil
    parts) is a mistake: it would be measured as two captures."""
    for name in roles:
        value = params.get(name)
        if not isinstance(value, (list, tuple)):
            continue
        seen: dict[str, str] = {}
        for item in value:
            key = os.path.realpath(item)
            if key in seen:
                raise InputError(f"{item} is given twice as {name.upper()}; give each file once")
            seen[key] = item


_TABLE = (
    Stage("decode", inputs=("input", "calib"), outputs=("output", "preview")),
    Stage("bias", inputs=("input",), outputs=("output", "preview")),
    Stage("flat", inputs=("input", "white", "gain"), outputs=("output", "save_gain", "preview")),
    Stage("calibrate", inputs=("input", "compare", "start"), outputs=("output", "xml", "preview")),
    Stage("refocus", inputs=("input", "grid", "depth"), outputs=("output", "preview")),
    Stage("depth", inputs=("input", "grid", "camera"), outputs=("output", "preview")),
    Stage("sai", inputs=("input", "grid"), outputs=("output", "preview")),
    Stage("crosstalk", inputs=("inputs", "grid"), outputs=("output", "preview", "mixing_out")),
    Stage("unmix", inputs=("inputs", "mixing"), outputs=("output", "noise_map", "preview")),
    Stage("stitch", inputs=("inputs", "transform_in", "rig"),
          outputs=("output", "transform_out", "report", "preview")),
    Stage("develop", inputs=("input", "wb_from", "recover_highlights"),
          outputs=("output", "linear", "preview")),
    Stage("optics", inputs=("input",), outputs=("json",)),
    Stage("simulate", inputs=(), outputs=("output",), folder_outputs=("output",)),
)


def get_stages() -> dict[str, Stage]:
    """All registered stages by name."""
    return {s.name: s for s in _TABLE}


def get_stage(name: str) -> Stage:
    """One stage by name (ConfigError naming the stages when unknown)."""
    stages = get_stages()
    if name not in stages:
        raise ConfigError(f"unknown stage {name!r}; stages: {', '.join(stages)}")
    return stages[name]
