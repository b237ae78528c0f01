"""One parameter path: a YAML step or ``--set`` value goes through its command's own click types.

A stage's click command defines each parameter once (type, range, choices, default). Values from
a config are turned into the words a shell would pass (``--smooth=9``) and parsed by that same
command, so a config can never do what the shell cannot, and the result is the fully resolved
parameter set, defaults included, that the stage runs with and records.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import click

from plenocli.errors import ConfigError

# Options every command has (verbosity, tracebacks): not stage parameters.
EDGE_OPTIONS = ("verbose", "quiet", "debug")


def stage_parameters(command: click.Command) -> dict[str, click.Parameter]:
    """The command's parameters by keyword name, without the edge options."""
    return {p.name: p for p in command.params if p.name and p.name not in EDGE_OPTIONS}


def defaults(command: click.Command) -> dict[str, Any]:
    """Each stage parameter's default as the command resolves it (None for a required one)."""
    ctx = command.make_context(command.name, [], resilient_parsing=True)
    return {k: v for k, v in ctx.params.items() if k not in EDGE_OPTIONS}


def argv_for(command: click.Command, values: Mapping[str, Any]) -> list[str]:
    """The shell words that give ``command`` these parameter values (None = not given).

    A list for a one-value option is the comma-separated word the shell would take
    (``g: [2, 3]`` is ``--g=2,3``); the option's type then accepts or refuses it. Raises
    ConfigError for a value no shell word could carry (a mapping, a nested list, a non-boolean
    for a flag, a list for one file path).
    """
    params = stage_parameters(command)
    options: list[str] = []
    positional: list[str] = []
    for name, value in values.items():
        param = params.get(name)
        if param is None:
            raise ConfigError(f"{command.name} has no parameter {name!r}")
        if value is None:
            continue
        if isinstance(value, Mapping):
            raise ConfigError(f"{_label(param)}: expected a value, got a mapping {dict(value)!r}")
        many = param.multiple if isinstance(param, click.Option) else param.nargs != 1
        items = list(value) if isinstance(value, (list, tuple)) else [value]
        if len(items) != 1 and not many:
            if isinstance(param.type, click.Path):  # a comma is part of a file name
                raise ConfigError(f"{_label(param)}: expected one file path, got a list "
                                  f"{items!r}")
            if isinstance(param, click.Argument) or param.is_flag or not items:
                raise ConfigError(f"{_label(param)}: expected one value, got a list {items!r}")
            items = [",".join(_word(param, v) for v in items)]
        if isinstance(param, click.Argument):
            positional.extend(_word(param, v) for v in items)
        elif param.is_flag:
            options.extend(_flag_words(param, items[0]))
        else:
            flag = max(param.opts, key=len)
            for item in items:
                word = _word(param, item)
                options.extend([f"{flag}={word}"] if flag.startswith("--") else [flag, word])
    if any(word.startswith("-") for word in positional):
        return [*options, "--", *positional]
    return [*positional, *options]


def resolve(command: click.Command, values: Mapping[str, Any]) -> dict[str, Any]:
    """Parse ``values`` with ``command`` exactly as the shell's words would be parsed.

    Returns every stage parameter of the command (defaults included), converted and checked by
    its click type. Raises ConfigError with click's own message for a bad value.
    """
    argv = argv_for(command, values)
    try:
        ctx = command.make_context(command.name, argv, resilient_parsing=False)
    except click.ClickException as err:
        raise ConfigError(" ".join(err.format_message().split())) from err
    return {k: v for k, v in ctx.params.items() if k not in EDGE_OPTIONS}


def _label(param: click.Parameter) -> str:
    return max(param.opts, key=len) if isinstance(param, click.Option) else param.name.upper()


def _word(param: click.Parameter, value: Any) -> str:
    if isinstance(value, (list, tuple, Mapping)):
        raise ConfigError(f"{_label(param)}: expected a plain value, got {value!r}")
    if isinstance(value, bool):
        return "true" if value else "false"
    if "\0" in str(value):
        raise ConfigError(f"{_label(param)}: {value!r} holds a NUL character, which no shell "
                          "word (and no file name) can")
    return str(value)


def _flag_words(param: click.Option, value: Any) -> list[str]:
    if not isinstance(value, bool):
        raise ConfigError(f"{_label(param)}: expected true or false, got {value!r}")
    if value:
        return [param.opts[0]]
    if param.secondary_opts:
        return [param.secondary_opts[0]]
    return []  # a plain flag left off
