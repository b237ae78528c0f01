"""Makefile fragments: a pipeline config as make rules, for users who drive plenocli with make.

One rule per step: targets = the step's outputs (a grouped target ``a b &: ...`` when there are
several, GNU make >= 4.3), prerequisites = its inputs and the config file, recipe = the
``plenocli STAGE`` command with the step's parameters as options. make then rebuilds exactly what
is out of date, in parallel with ``make -j``. The command is ``$(PLENOCLI)`` (default
``plenocli``), so ``make PLENOCLI="python -m plenocli"`` works without the script.
"""

from __future__ import annotations

import os
import re
import shlex
from collections.abc import Sequence
from pathlib import Path

from plenocli.errors import ConfigError
from plenocli.pipeline.config import Step
from plenocli.pipeline.params import shell_words
from plenocli.pipeline.runner import check_inputs

_UNSAFE = re.compile(r"[^\w.+,@~/-]")  # spaces, :, =, $, #, quotes, globs: not in make names


def make_fragment(steps: Sequence[Step], config: str | Path, *,
                  base: str | Path | None = None, command: str = "") -> str:
    """Make rules for ``steps``, in order (a file written by two of them is refused).

    ``base``: paths inside this folder are written relative to it (default: the current folder;
    run make from there); others stay absolute. ``command``: the plenocli invocation that made
    the fragment, recorded in its header.
    """
    check_inputs(list(steps))  # what plenocli run refuses, make is not given either
    root = Path(base or Path.cwd()).resolve()
    config_path = _name(Path(config), root)
    writer: dict[str, str] = {}
    rules: list[str] = []
    finals: list[str] = []
    folders: set[Path] = set()  # folder outputs: a file read in one depends on the folder
    for step in steps:
        outputs = tuple(_name(p, root) for p in step.output_paths())
        if not outputs:
            raise ConfigError(f"step {step.name!r} writes no file, so make cannot track it")
        for name in outputs:
            if name in writer:
                raise ConfigError(f"steps {writer[name]!r} and {step.name!r} both write {name}; "
                                  "give each its own output path")
            writer[name] = step.name
        finals.extend(outputs)
        prerequisites = [_name(_target(p, folders), root) for p in step.input_paths()]
        prerequisites.append(config_path)
        folders.update(Path(os.path.abspath(p))
                       for p in step.stage.paths(step.params, step.stage.folder_outputs))
        separator = "&:" if len(outputs) > 1 else ":"
        rules.append(f"# step {step.name}\n{' '.join(outputs)} {separator} "
                     f"{' '.join(dict.fromkeys(prerequisites))}\n\t{_recipe(step, root)}\n")
    header = [
        "# Makefile fragment made by plenocli" + (f": {command}" if command else ""),
        f"# Paths are relative to {root}: run make there. Needs GNU make >= 4.3 (grouped '&:').",
        "PLENOCLI ?= plenocli",
        "PLENOCLI_OUTPUTS += \\\n  " + " \\\n  ".join(finals),
        "",
        ".PHONY: plenocli-all",
        "plenocli-all: $(PLENOCLI_OUTPUTS)",
        "",
    ]
    return "\n".join(header) + "\n" + "\n".join(rules)


def _recipe(step: Step, root: Path) -> str:
    """The shell command of a step: the values the config gave, in the command's own words."""
    values = {}
    for key in step.given:
        value = step.params[key]
        if key in step.stage.inputs or key in step.stage.outputs:
            many = isinstance(value, (list, tuple))
            names = [None if v is None else _name(Path(v), root)
                     for v in (value if many else [value])]
            value = names if many else names[0]
        values[key] = value
    words = shell_words(step.stage.params, values)
    return " ".join(["$(PLENOCLI)", step.stage.name, *(_quote(w) for w in words)])


def _target(path: Path, folders: set[Path]) -> Path:
    """The make target that provides ``path``: the folder output holding it, or itself."""
    full = Path(os.path.abspath(path))
    return next((parent for parent in full.parents if parent in folders), full)


def _quote(value) -> str:
    """A shell word, with '$' doubled for make."""
    return shlex.quote(str(value)).replace("$", "$$")


def _name(path: Path, root: Path) -> str:
    """A path as a make target name: relative to ``root`` when inside it."""
    resolved = Path(os.path.abspath(path))
    try:
        text = str(resolved.relative_to(root))
    except ValueError:
        text = str(resolved)
    bad = _UNSAFE.search(text) or re.match("~", text)  # make reads ~NAME/ as a home folder
    if bad:
        shown = {" ": "a space", "\t": "a tab", "\n": "a line break"}.get(
            bad.group(), f"'{bad.group()}'")
        raise ConfigError(f"path {text} has {shown}, which make or the shell would misread; "
                          "rename the file or folder, or use plenocli batch instead")
    return text
