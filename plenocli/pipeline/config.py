"""Pipeline configs: YAML files that chain stages.

::

    description: what this pipeline is for
    steps:
      decode_white:            # a step name (used by --set decode_white.camera=dng)
        stage: decode          # may be left out when the step name is a stage name
        input: white.CR2       # relative paths resolve against this file's folder
        output: out/white_frames.tif
      bias_white: {stage: bias, input: out/white_frames.tif, smooth: 9,
                   output: out/white_biased.tif}

The keys of a step are its stage's long option names (``mask-width`` or ``mask_width``). Unknown
keys are errors that name the closest valid key.

Batch templates (``plenocli batch``): a value may hold the placeholders ``{capture}`` (the path of
one capture), ``{name}`` (its file name without suffix) and ``{out}`` (the output root: the
top-level ``out:`` key, relative to this file, or ``--out DIR``). Steps that use ``{capture}`` or
``{name}`` run once per capture and must put ``{name}`` (or ``{capture}``) in every output path;
the other steps (white image, calibration) are shared: they run once and every capture reuses
their outputs::

    out: ../out/batch
    steps:
      decode_white: {stage: decode, input: white.dng, output: "{out}/white_frames.tif"}
      decode:       {input: "{capture}", output: "{out}/{name}/frames.tif"}
"""

from __future__ import annotations

import difflib
import inspect
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from plenocli.errors import ConfigError, InputError, OptionError, value_words
from plenocli.io.atomic import check_distinct
from plenocli.io.yamlfile import DocumentError, comment_advice, comment_in, load_yaml
from plenocli.pipeline.registry import Stage, get_stages
from plenocli.pipeline.validators import FiniteFloat, Int, shell_text

TOP_KEYS = ("description", "steps", "out")
PER_CAPTURE = ("capture", "name")  # placeholders that make a step run once per capture
_PLACEHOLDER = re.compile(r"\{(capture|name|out)\}")
_ANY_PLACEHOLDER = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*)\}")


@dataclass(frozen=True)
class Step:
    name: str
    stage: Stage
    params: dict[str, Any]  # every parameter, resolved by the declaration; paths absolute
    given: tuple[str, ...] = ()  # the parameters the config named (the rest are defaults)

    def input_paths(self) -> list[Path]:
        return self.stage.paths(self.params, self.stage.inputs)

    def output_paths(self) -> list[Path]:
        return self.stage.paths(self.params, self.stage.outputs)


def closest(word: str, choices) -> str:
    """' (did you mean X?)' or ''."""
    match = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    return f" (did you mean {match[0]!r}?)" if match else ""


def load_config(path: str | Path, overrides: list[str] = ()) -> list[Step]:
    """Read, validate and resolve a pipeline config; ``overrides`` are ``STEP.PARAM=VALUE``."""
    template = read_template(path, overrides)
    if template.per_capture_steps():
        raise ConfigError(f"{template.path}: a batch template (steps "
                          f"{', '.join(sorted(template.per_capture_steps()))} use {{capture}} or "
                          "{name}); run it with plenocli batch CONFIG --inputs CAPTURES")
    return template.steps()


@dataclass(frozen=True)
class Template:
    """A config as written (placeholders kept, overrides applied), before paths are resolved."""

    path: Path
    raw_steps: dict[str, dict]
    out: str | None  # the top-level 'out:' value (relative to the config's folder)

    def uses_out(self) -> bool:
        """Whether a step names ``{out}`` (else an output root has nothing to fill)."""
        return any("out" in _placeholders(body) for body in self.raw_steps.values())

    def per_capture_steps(self) -> set[str]:
        """Names of the steps that use ``{capture}`` or ``{name}``."""
        return {name for name, body in self.raw_steps.items()
                if _placeholders(body) & set(PER_CAPTURE)}

    def steps(self, *, capture: str | Path | None = None, out: str | Path | None = None,
              only: str = "all") -> list[Step]:
        """Resolved steps with the placeholders filled in.

        ``capture``: the capture's path (needed by per-capture steps); ``out``: the output root
        (overrides the config's ``out:``); ``only``: "all", "shared" or "per-capture" steps.
        """
        if only not in ("all", "shared", "per-capture"):
            raise ValueError(f"only must be all, shared or per-capture, got {only!r}")
        if out is not None and not self.uses_out():
            raise OptionError(f"--out {out}: no step of {self.path} uses {{out}}, so it would "
                              "change nothing (the outputs are the paths the steps name); "
                              "leave --out out, or write the outputs as {out}/...")
        base = self.path.resolve().parent
        per_capture = self.per_capture_steps()
        values = self._values(capture, out)
        stages = get_stages()
        steps = []
        for name, body in self.raw_steps.items():
            if only != "all" and (name in per_capture) != (only == "per-capture"):
                continue
            missing = _placeholders(body) - set(values)
            if missing:
                what = ("--out DIR or a top-level 'out:' key" if missing == {"out"}
                        else "a capture (plenocli batch CONFIG --inputs CAPTURES)")
                raise ConfigError(f"{self.path}: step {name!r} uses "
                                  f"{', '.join('{' + m + '}' for m in sorted(missing))}; "
                                  f"give {what}")
            steps.append(_make_step(self.path, base, name, _fill(body, values), stages))
        _check_files(self.path, steps)
        return steps

    def _values(self, capture: str | Path | None, out: str | Path | None) -> dict[str, str]:
        """What the placeholders stand for."""
        values = {}
        if capture is not None:
            name = Path(capture).stem
            if name in ("", ".", ".."):  # {out}/{name}/x would leave {out}, onto another file
                raise InputError(f"capture {capture}: its name {name!r} cannot name a folder; "
                                 "rename the file")
            values = {"capture": str(Path(capture).parent.resolve() / Path(capture).name),
                      "name": name}  # the folder resolved (for workers), the name as given
        base = self.path.resolve().parent
        root = out if out is not None else (str(base / self.out) if self.out else None)
        if root is not None:
            values["out"] = str(Path(root).resolve())
        return values

    def check_captures_apart(self, captures: list[str], *, out: str | None = None) -> None:
        """Before a batch: no capture's step writes a shared step's file or a capture (a
        capture named like a shared output would overwrite it for every capture after it).
        Only the output paths are filled in per capture: fast for thousands of captures."""
        taken = {os.path.abspath(c): "a capture" for c in captures}
        for step in self.steps(out=out, only="shared"):
            taken.update({os.path.abspath(p): f"an input of shared step {step.name!r}"
                          for p in step.input_paths()})
            taken.update({os.path.abspath(p): f"the output of shared step {step.name!r}"
                          for p in step.output_paths()})
        for capture, name, path in self._per_capture_outputs(captures, out):
            what = taken.get(path)
            if what:
                raise ConfigError(f"capture {capture}: step {name!r} would write {path}, "
                                  f"{what}; give {self.path} per-capture outputs apart, "
                                  "e.g. under {out}/{name}/")

    def outputs_of(self, captures: list[str], *, out: str | None = None) -> set[str]:
        """The absolute paths a batch of ``captures`` writes: the shared steps' outputs and
        every capture's own."""
        made = {os.path.abspath(p) for step in self.steps(out=out, only="shared")
                for p in step.output_paths()}
        made.update(path for _, _, path in self._per_capture_outputs(captures, out))
        return made

    def written_by(self, *, out: str | None = None) -> re.Pattern:
        """What the files a batch of any captures writes match (absolute paths, a file in or
        under an output): the shared steps' outputs and every capture's own, its {name} and
        {capture} standing for any."""
        marks = {"name": "\x01name\x01", "capture": "/\x01capture\x01"}
        values = {**self._values(None, out), **marks}
        base = self.path.resolve().parent
        shared = [os.path.abspath(p) for step in self.steps(out=out, only="shared")
                  for p in step.output_paths()]
        alternatives = [re.escape(p) for p in shared]
        for name in self.per_capture_steps():
            items = self._outputs_of_step(name)
            if _placeholders(items) - set(values):
                continue  # no {out}: the batch refuses the config, with the reason
            for path in _flat(_resolve(base, _fill(items, values))):
                pattern = re.escape(os.path.normpath(path))
                for mark, stands_for in ((marks["name"], "[^/]+"), (marks["capture"], "/.+")):
                    pattern = pattern.replace(re.escape(mark), stands_for)
                alternatives.append(pattern)
        return re.compile("(?:" + "|".join(alternatives or ["(?!)"]) + ")(?:/.*)?", re.S)

    def _outputs_of_step(self, name: str) -> list:
        """The output values of step ``name`` as written (placeholders kept)."""
        stage = get_stages().get(self.raw_steps[name].get("stage", name))
        roles = stage.outputs if stage is not None else ()  # unknown: said by steps()
        return [v for k, v in self.raw_steps[name].items() if str(k).replace("-", "_") in roles]

    def _per_capture_outputs(self, captures: list[str], out: str | None):
        """(capture, step name, absolute output path) of every per-capture step."""
        base = self.path.resolve().parent
        outputs = {name: self._outputs_of_step(name) for name in self.per_capture_steps()}
        for capture in captures:
            values = self._values(capture, out)
            for name, items in outputs.items():
                for path in _flat(_resolve(base, _fill(items, values))):
                    yield capture, name, os.path.abspath(path)


def read_template(path: str | Path, overrides: list[str] = ()) -> Template:
    """Read and check a config's structure; placeholders are kept (see :class:`Template`)."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: no such config file")
    if not p.is_file():
        raise ConfigError(f"{p}: not a regular file; give a YAML config file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise ConfigError(f"{p}: not valid YAML (not UTF-8 text, byte {err.start})") from err
    except OSError as err:
        raise ConfigError(f"{p}: cannot read the config ({err.strerror})") from err
    try:
        doc = load_yaml(text, words=True)
    except DocumentError as err:
        hint = ("; quote values that start with a placeholder, e.g. \"{out}/x.tif\""
                if _PLACEHOLDER.search(text) else "")
        raise ConfigError(f"{p}: not valid YAML ({err}){hint}") from err
    if not isinstance(doc, dict) or not isinstance(doc.get("steps"), dict):
        raise ConfigError(f"{p}: a config needs a 'steps:' mapping of step names to stages")
    if not doc["steps"]:
        raise ConfigError(f"{p}: its 'steps:' mapping is empty; give it one step at least")
    for key in doc:
        if key not in TOP_KEYS:
            raise ConfigError(f"{p}: unknown top-level key {key!r}{closest(key, TOP_KEYS)}")
    if not isinstance(doc.get("description", ""), (str, type(None))):
        # info shows it as the config's line of text; a number or a list is no description
        raise ConfigError(f"{p}: 'description:' must be text (quote it), got "
                          f"{value_words(doc['description'])}")
    for name, body in doc["steps"].items():
        if not isinstance(name, str) or not name:
            what = "must not be empty" if isinstance(name, str) else "must be text (quote it)"
            raise ConfigError(f"{p}: step name {value_words(name)} {what}, e.g. 'bias2'")
        if not (body is None or isinstance(body, dict)):
            raise ConfigError(f"{p}: step {name!r} must be a mapping of parameters "
                              f"(e.g. input: ..., output: ...), got {value_words(body)}")
        if not isinstance((body or {}).get("stage", ""), str):
            raise ConfigError(f"{p}: step {name!r}: stage must be one stage name, got "
                              f"{value_words(body['stage'])}")
    raw_steps = {name: {k: _unflow(v) for k, v in dict(body or {}).items()}
                 for name, body in doc["steps"].items()}
    _apply_overrides(p, raw_steps, overrides)
    _check_placeholder_names(p, raw_steps)
    template = Template(p, raw_steps, doc.get("out"))
    _check_out_key(template)
    _check_per_capture_outputs(template)
    return template


def _check_out_key(template: Template) -> None:
    """The top-level ``out:``: one plain folder path, filling a ``{out}`` some step uses."""
    p, out = template.path, template.out
    if out is None:
        return
    if not isinstance(out, str):
        raise ConfigError(f"{p}: 'out:' must be one folder path, got {value_words(out)}")
    if _ANY_PLACEHOLDER.search(out):
        # what {out} stands for: nothing fills a placeholder in it (it would name a folder '{out}')
        raise ConfigError(f"{p}: 'out:' {out!r} holds a placeholder; give a plain folder path "
                          "(per-capture folders go in the steps, e.g. {out}/{name}/x.tif)")
    if not template.uses_out():
        raise ConfigError(f"{p}: 'out: {out}' fills {{out}}, which no step uses (the outputs "
                          "are the paths the steps name); remove it, or write the outputs as "
                          "{out}/...")


def _unflow(value):
    """YAML reads an unquoted ``{capture}`` as the mapping {capture: None}: take it back."""
    if (isinstance(value, dict) and len(value) == 1 and None in value.values()
            and next(iter(value)) in ("capture", "name", "out")):
        return "{" + next(iter(value)) + "}"
    return value


def _check_placeholder_names(path: Path, raw_steps: dict) -> None:
    """A placeholder other than {capture}, {name}, {out} would be written literally into a
    file name (a file named '{foo}.tif')."""
    known = ("capture", "name", "out")
    for name, body in raw_steps.items():
        for key, value in body.items():
            unknown = [w for v in _flat(value) if isinstance(v, str)
                       for w in _ANY_PLACEHOLDER.findall(v) if w not in known]
            if unknown:
                raise ConfigError(f"{path}: step {name!r}: {key}: unknown placeholder "
                                  f"{{{unknown[0]}}}{closest(unknown[0], known)}; the "
                                  "placeholders are {capture}, {name} and {out}")


def _placeholders(value) -> set[str]:
    if isinstance(value, str):
        return set(_PLACEHOLDER.findall(value))
    if isinstance(value, dict):
        return set().union(*(_placeholders(v) for v in value.values()))
    if isinstance(value, (list, tuple)):
        return set().union(*(_placeholders(v) for v in value))
    return set()


def _fill(value, values: dict[str, str]):
    if isinstance(value, str):
        return _PLACEHOLDER.sub(lambda m: values[m.group(1)], value)
    if isinstance(value, dict):
        return {k: _fill(v, values) for k, v in value.items()}
    if isinstance(value, list):  # not a tuple (an !!omap pair): no path, refused as it is
        return [_fill(v, values) for v in value]
    return value


def _check_per_capture_outputs(template: Template) -> None:
    """Every output of a per-capture step must name the capture, or captures overwrite it."""
    stages = get_stages()
    for name in template.per_capture_steps():
        body = template.raw_steps[name]
        stage = stages.get(body.get("stage", name))
        if stage is None:
            continue  # reported with a better message by _make_step
        for key, value in body.items():
            if str(key).replace("-", "_") not in stage.outputs or value is None:
                continue
            for item in value if isinstance(value, (list, tuple)) else [value]:
                if not _placeholders(item) & set(PER_CAPTURE):
                    raise ConfigError(
                        f"{template.path}: step {name!r} runs once per capture but writes "
                        f"{key}: {item} for every capture; put {{name}} in the path, e.g. "
                        f"{{out}}/{{name}}/{Path(str(item)).name}")


def _check_files(path: Path, steps: list[Step]) -> None:
    """Before any step runs: no two steps write one file (or into a folder another fills), no
    step writes its own input or the config, and no step reads what a later step writes (steps
    out of order, or a cycle: the runner would read a stale file, make would drop the cycle)."""
    writer: dict[str, int] = {}
    config = os.path.realpath(path)
    for k, step in enumerate(steps):
        try:
            check_distinct(step.output_paths(), step.input_paths())
        except InputError as err:
            raise ConfigError(f"{path}: step {step.name!r}: {err}") from err
        for out in step.output_paths():
            key = os.path.abspath(out)
            if os.path.realpath(out) == config:
                raise ConfigError(f"{path}: step {step.name!r} would write over this config "
                                  f"({out}); choose another output path")
            if key in writer:
                raise ConfigError(f"{path}: steps {steps[writer[key]].name!r} and {step.name!r} "
                                  f"both write {out}; give each step its own output path")
            writer[key] = k
    folders = {os.path.abspath(f): k for k, step in enumerate(steps)
               for f in step.stage.paths(step.params, step.stage.folder_outputs)}
    for key, k in writer.items():
        under = [f for f in Path(key).parents if str(f) in writer and str(f) not in folders]
        if under:
            raise ConfigError(f"{path}: step {steps[k].name!r} writes {key} under {under[0]}, "
                              f"the output file of step {steps[writer[str(under[0])]].name!r} "
                              "(a file cannot hold a folder); write it elsewhere")
    for key, k in writer.items():
        inside = [folders[str(f)] for f in Path(key).parents if folders.get(str(f), k) != k]
        if inside:
            raise ConfigError(f"{path}: step {steps[k].name!r} writes {key} inside the folder "
                              f"that step {steps[inside[0]].name!r} fills; write it elsewhere")
    for k, step in enumerate(steps):
        for p in step.input_paths():
            full = Path(os.path.abspath(p))
            later = [writer[str(f)] for f in (full, *full.parents) if writer.get(str(f), -1) > k]
            if later:
                other = steps[later[0]].name
                raise ConfigError(f"{path}: step {step.name!r} reads {p}, which step {other!r} "
                                  f"writes after it; put {other!r} before {step.name!r} (steps "
                                  "that read each other's outputs cannot run)")


def _apply_overrides(path: Path, steps: dict, overrides) -> None:
    """``--set STEP.PARAM=VALUE``: each replaces the config's key however it is spelled
    (``save-gain`` or ``save_gain``); one parameter set twice is refused (which one holds?)."""
    given: dict[tuple[str, str], str] = {}
    for item in overrides:
        target, sep, value = item.partition("=")
        step, dot, param = target.rpartition(".")  # step names may hold dots; keys never
        if not sep or not dot or not param:
            raise OptionError(f"--set {item!r}: expected STEP.PARAM=VALUE, e.g. bias.smooth=9")
        # Faults in the --set words themselves are the command line's: usage errors (exit 2).
        if step not in steps:
            raise OptionError(f"--set {item!r}: {path} has no step {step!r}"
                              f"{closest(step, steps)}")
        if param == "stage":
            raise OptionError(f"--set {item!r}: a step's stage is not a parameter; edit "
                              f"{path} to change it")
        norm = param.replace("-", "_")
        if (step, norm) in given:
            raise OptionError(f"--set {item!r}: {step}.{param} is already set by --set "
                              f"{given[step, norm]!r}; keep one")
        given[step, norm] = item
        for key in [k for k in steps[step] if str(k).replace("-", "_") == norm]:
            del steps[step][key]
        try:  # an empty value is the empty word, as --smooth= in the shell
            parsed = _unflow(load_yaml(value, words=True)) if value != "" else ""
        except DocumentError as err:
            raise OptionError(f"--set {item!r}: the value is not valid YAML ({err}); "
                              "quote it") from err
        if isinstance(parsed, Mapping):  # 'g= 2 : 8' reads as YAML's {2: 8}: no shell word
            parsed = value
        elif value != "" and (comment := comment_in(value)) is not None:
            raise OptionError(f"--set {item!r}: {comment_advice(target, value, comment)}")
        _check_set_value(f"--set {item!r}: step {step!r}", path, steps[step].get("stage", step),
                         norm, parsed)
        steps[step][param] = parsed


def _check_set_value(said: str, path: Path, stage_name: str, name: str, value: Any) -> None:
    """A --set key and value get their parameter's check now, as a flag would: a key the stage
    does not take, or a value wrong by itself, is a usage error (OptionError). Values with
    placeholders wait to be filled per capture (a number's are refused now); a step of an
    unknown stage is the config's to refuse."""
    from plenocli.pipeline.params import convert

    stage = get_stages().get(stage_name)
    if stage is None:
        return
    if name not in stage.parameters():
        options = [k.replace("_", "-") for k in stage.parameters()]
        raise OptionError(f"{said}: stage {stage_name} has no parameter "
                          f"{name.replace('_', '-')!r}{closest(name.replace('_', '-'), options)}")
    param = {p.name: p for p in stage.params}.get(name)
    if param is None or _placeholders(value):
        if param is not None and isinstance(param.type, (Int, FiniteFloat)):  # never a number
            raise OptionError(f"{said}: {name.replace('_', '-')} takes a number, not a capture's"
                              " path, name or folder ({capture}, {name}, {out})")
        return
    if value is None:  # the shell has no word for "no value": null would mean the default
        raise OptionError(f"{said}: {name.replace('_', '-')} has no value (null or "
                          "empty); give one, or leave the --set out for the config's value")
    if param.type.is_path:
        value = _resolve(path.resolve().parent, value)  # as the step will read it
    try:
        convert(param, value)
    except ConfigError as err:
        raise OptionError(f"{said}: {err}") from err


def _make_step(path: Path, base: Path, name: str, body: dict, stages: dict) -> Step:
    stage_name = body.pop("stage", name)
    if stage_name not in stages:
        raise ConfigError(f"{path}: step {name!r}: unknown stage {stage_name!r}"
                          f"{closest(str(stage_name), stages)}; add 'stage: NAME'")
    stage = stages[stage_name]
    valid = stage.parameters()
    given: dict[str, Any] = {}
    for key, value in body.items():
        norm = str(key).replace("-", "_")
        if norm in given:
            raise ConfigError(f"{path}: step {name!r}: {norm.replace('_', '-')} is given twice "
                              "(as KEY-NAME and KEY_NAME); keep one")
        if norm not in valid:
            options = [k.replace("_", "-") for k in valid]
            raise ConfigError(f"{path}: step {name!r}: unknown key {key!r} for stage "
                              f"{stage_name}{closest(str(key).replace('_', '-'), options)}")
        if value is None:  # the shell has no word for "no value": null would mean the default
            raise ConfigError(f"{path}: step {name!r}: {key} has no value (null or empty); "
                              "give one, or leave the key out for the default")
        if norm in stage.inputs or norm in stage.outputs:
            value = _resolve(base, value)
        given[norm] = value
    missing = [k for k, d in valid.items() if d is inspect.Parameter.empty and k not in given]
    if missing:
        raise ConfigError(f"{path}: step {name!r}: missing {', '.join(missing)} "
                          f"(required by stage {stage_name})")
    try:
        params = stage.resolve(given)
    except ConfigError as err:
        raise ConfigError(f"{path}: step {name!r}: {err}") from err
    return Step(name, stage, params, tuple(given))


def _flat(value) -> list:
    """The strings in a value that may be a list (of lists)."""
    if isinstance(value, (list, tuple)):
        return [v for item in value for v in _flat(item)]
    return [] if value is None else [value]


def _resolve(base: Path, value):
    if isinstance(value, list):
        return [_resolve(base, v) for v in value]
    if not isinstance(value, (str, int, float)) or value == "" or "\0" in str(value):
        # refused by its validator as the shell's word would be; a YAML set, date or binary
        # (or pairs, !!omap) is no path: made into one, it would name a file "b'a'"
        return value
    word = shell_text(value)   # the word written: `false`, not Python's False
    return str((base / word).resolve()) if not Path(word).is_absolute() else word
