"""Pipeline configs: YAML files that chain stages.

::

    description: what this pipeline is for
    steps:
      decode_white:            # a step name (used by --set decode_white.camera=dng)
        stage: decode          # may be left out when the step name is a stage name
        input: white.CR2       # relative paths resolve against this file's folder
        output: out/white_frames.tif
      bias_white:
        stage: bias
        input: out/white_frames.tif
        smooth: 9
        output: out/white_biased.tif

The keys of a step are its stage's long option names (``mask-width`` or ``mask_width``). Unknown
keys are errors that name the closest valid key.
"""

from __future__ import annotations

import difflib
import inspect
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from plenocli.errors import ConfigError
from plenocli.pipeline.registry import Stage, get_stages

TOP_KEYS = ("description", "steps")


@dataclass(frozen=True)
class Step:
    name: str
    stage: Stage
    params: dict[str, Any]  # keyword names of stage.run, paths resolved

    def input_paths(self) -> list[Path]:
        return _paths(self.params, self.stage.inputs)

    def output_paths(self) -> list[Path]:
        return _paths(self.params, self.stage.outputs)


def _paths(params: dict, names: tuple[str, ...]) -> list[Path]:
    out: list[Path] = []
    for name in names:
        value = params.get(name)
        if value is None:
            continue
        out.extend(Path(v) for v in (value if isinstance(value, (list, tuple)) else [value]))
    return out


def closest(word: str, choices) -> str:
    """' (did you mean X?)' or ''."""
    match = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    return f" (did you mean {match[0]!r}?)" if match else ""


def load_config(path: str | Path, overrides: list[str] = ()) -> list[Step]:
    """Read, validate and resolve a pipeline config; ``overrides`` are ``STEP.PARAM=VALUE``."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such config file")
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise ConfigError(f"{p}: not valid YAML ({str(err).splitlines()[0]})") from err
    if not isinstance(doc, dict) or not isinstance(doc.get("steps"), dict) or not doc["steps"]:
        raise ConfigError(f"{p}: a config needs a 'steps:' mapping of step names to stages")
    for key in doc:
        if key not in TOP_KEYS:
            raise ConfigError(f"{p}: unknown top-level key {key!r}{closest(key, TOP_KEYS)}")
    raw_steps = {name: dict(body or {}) for name, body in doc["steps"].items()}
    _apply_overrides(p, raw_steps, overrides)
    stages = get_stages()
    base = p.resolve().parent
    return [_make_step(p, base, name, body, stages) for name, body in raw_steps.items()]


def _apply_overrides(path: Path, steps: dict, overrides) -> None:
    for item in overrides:
        target, sep, value = item.partition("=")
        step, dot, param = target.partition(".")
        if not sep or not dot or not param:
            raise ConfigError(f"--set {item!r}: expected STEP.PARAM=VALUE, e.g. bias.smooth=9")
        if step not in steps:
            raise ConfigError(f"--set {item!r}: {path} has no step {step!r}"
                              f"{closest(step, steps)}")
        steps[step][param] = yaml.safe_load(value) if value != "" else None


def _make_step(path: Path, base: Path, name: str, body: dict, stages: dict) -> Step:
    stage_name = body.pop("stage", name)
    if stage_name not in stages:
        raise ConfigError(f"{path}: step {name!r}: unknown stage {stage_name!r}"
                          f"{closest(str(stage_name), stages)}; add 'stage: NAME'")
    stage = stages[stage_name]
    valid = stage.parameters()
    params: dict[str, Any] = {}
    for key, value in body.items():
        norm = str(key).replace("-", "_")
        if norm not in valid:
            options = [k.replace("_", "-") for k in valid]
            raise ConfigError(f"{path}: step {name!r}: unknown key {key!r} for stage "
                              f"{stage_name}{closest(str(key).replace('_', '-'), options)}")
        if norm in stage.inputs or norm in stage.outputs:
            value = _resolve(base, value)
        params[norm] = value
    missing = [k for k, d in valid.items() if d is inspect.Parameter.empty and k not in params]
    if missing:
        raise ConfigError(f"{path}: step {name!r}: missing {', '.join(missing)} "
                          f"(required by stage {stage_name})")
    return Step(name, stage, params)


def _resolve(base: Path, value):
    if value is None:
        return None
    if isinstance(value, (list, tuple)):
        return [_resolve(base, v) for v in value]
    return str((base / str(value)).resolve()) if not Path(str(value)).is_absolute() else str(value)
