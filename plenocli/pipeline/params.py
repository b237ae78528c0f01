"""Stage parameters, declared once, below the command line.

Each stage lists its parameters in ``plenocli/pipeline/schema/<stage>.py`` as a tuple ``PARAMS``
of :class:`Param`: name (the keyword of the stage's ``run``), a validator, help text, default,
role (a file the stage reads or writes, a folder it fills, or a plain value), flag spellings,
whether it repeats and whether it is required. A validator (:mod:`plenocli.pipeline.validators`)
converts and checks one value given as shell text or as a YAML value and raises ValueError
with the message a user sees.

Two readers: the command line builds its click options from the declaration (one adapter,
``cli/options.py``), and the runner resolves a YAML step or ``--set`` value here
(:func:`resolve`), with the same validators, so a config can never do what the shell cannot.
"""

from __future__ import annotations

import contextvars
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from plenocli.errors import ConfigError, OptionError, value_words
from plenocli.pipeline.validators import (
    TIFF,
    Flag,
    InputFile,
    OutputFile,
    Validator,
    shell_text,
)

ROLES = ("value", "input", "output", "folder")  # folder: an output folder the stage fills


@dataclass(frozen=True)
class Param:
    """One stage parameter.

    ``flags``: the option's spellings (default ``--name`` with dashes); ``positional``: an
    argument instead of an option; ``multiple``: a repeatable option or an argument taking any
    number of values (the value is then a tuple); a :class:`~validators.Flag` validator makes
    an on/off switch.
    """

    name: str
    type: Validator
    help: str = ""
    default: Any = None
    role: str = "value"
    flags: tuple[str, ...] = ()
    positional: bool = False
    multiple: bool = False
    required: bool = False
    metavar: str | None = None

    def __post_init__(self):
        if self.role not in ROLES:
            raise ValueError(f"{self.name}: role must be one of {ROLES}, got {self.role!r}")
        if not self.flags and not self.positional:
            object.__setattr__(self, "flags", ("--" + self.name.replace("_", "-"),))

    @property
    def is_flag(self) -> bool:
        return isinstance(self.type, Flag)

    @property
    def label(self) -> str:
        """How messages name it: the longest flag, or the argument's name in capitals."""
        return max(self.flags, key=len) if self.flags else self.name.upper()

    @property
    def hint(self) -> str:
        """How click's "Invalid value for ..." names it, so both paths say the same."""
        if self.positional:
            return f"'{self.name.upper()}{'...' if self.multiple else ''}'"
        return " / ".join(f"'{flag}'" for flag in self.flags)

    @property
    def unset(self) -> Any:
        """The value when not given: () for a repeatable one, False for a switch."""
        if self.multiple:
            return ()
        return bool(self.default) if self.is_flag else self.default


def input_arg() -> Param:
    """The INPUT argument: one file the stage reads."""
    return Param("input", InputFile(), role="input", positional=True, required=True)


def inputs_arg() -> Param:
    """The INPUTS argument: one or more files the stage reads."""
    return Param("inputs", InputFile(), role="input", positional=True, multiple=True,
                 required=True)


def output_param(*suffixes: str) -> Param:
    """-o/--output: the file the stage writes, named with one of ``suffixes`` (any when none)."""
    return Param("output", OutputFile(*suffixes), "Output file (written atomically).",
                 role="output", flags=("-o", "--output"), required=True)


OUTPUT = output_param(*TIFF)
PREVIEW = Param("preview", OutputFile(".png"), "Also write a PNG preview here.", role="output")


def names_by_role(params: Sequence[Param], *roles: str) -> tuple[str, ...]:
    return tuple(p.name for p in params if p.role in roles)


def resolve(params: Sequence[Param], values: Mapping[str, Any]) -> dict[str, Any]:
    """Every parameter: the converted ``values`` (as a YAML step gives them; None = not given),
    the defaults for the rest. ConfigError with the shell's message for a bad value."""
    declared = {p.name: p for p in params}
    out = {p.name: p.unset for p in params}
    for name, value in values.items():
        param = declared.get(name)
        if param is None:
            raise ConfigError(f"no parameter {name!r}; parameters: {', '.join(declared)}")
        if value is not None:
            out[name] = convert(param, value)
    return out


def convert(param: Param, value: Any) -> Any:
    """One parameter's value as a YAML step gives it, checked as the shell's word would be.

    A list for a one-value option is the comma-separated word the shell would take
    (``g: [2, 3]`` is ``--g=2,3``); the validator then accepts or refuses it.
    """
    if isinstance(value, Mapping):
        raise ConfigError(f"{param.label}: expected a value, got {value_words(value)}")
    items = list(value) if isinstance(value, (list, tuple)) else [value]
    if param.multiple:
        return tuple(_one(param, item) for item in items)
    if len(items) != 1:
        if param.type.is_path:  # a comma is part of a file name
            raise ConfigError(f"{param.label}: expected one file path, got "
                              f"{value_words(items)}")
        if param.positional or param.is_flag or not items:
            raise ConfigError(f"{param.label}: expected one value, got {value_words(items)}")
        items = [",".join(shell_text(_plain(param, v)) for v in items)]
    if param.is_flag and not isinstance(items[0], bool):
        raise ConfigError(f"{param.label}: expected true or false, got "
                          f"{value_words(items[0])}")
    return _one(param, items[0])


def _plain(param: Param, value: Any) -> Any:
    # a YAML set, date or binary would be taken as Python's repr of it (a set in hash order)
    if not isinstance(value, (str, int, float)):
        raise ConfigError(f"{param.label}: expected a plain value (text, a number, true or "
                          f"false), got {value_words(value)}")
    if "\0" in str(value):
        raise ConfigError(f"{param.label}: {value!r} holds a NUL character, which no shell "
                          "word (and no file name) can")
    return value


def _one(param: Param, value: Any) -> Any:
    try:
        return param.type.convert(_plain(param, value))
    except ValueError as err:
        raise ConfigError(f"Invalid value for {param.hint}: {err}") from err


def shell_words(params: Sequence[Param], values: Mapping[str, Any]) -> list[str]:
    """The shell words that give the stage's command these resolved values."""
    declared = {p.name: p for p in params}
    options: list[str] = []
    positional: list[str] = []
    for name, value in values.items():
        param = declared[name]
        if value is None:
            continue
        items = list(value) if isinstance(value, (list, tuple)) else [value]
        if param.positional:
            positional.extend(shell_text(v) for v in items)
        elif param.is_flag:
            options.extend(param.flags[:1] if value else [])
        else:
            flag = param.label
            for item in items:
                word = shell_text(item)
                options.extend([f"{flag}={word}"] if flag.startswith("--") else [flag, word])
    if any(word.startswith("-") for word in positional):
        return [*options, "--", *positional]
    return [*positional, *options]


def refuse_unused(params: Sequence[Param], given: Collection[str], names: Sequence[str],
                  reason: str) -> None:
    """OptionError for the first of ``names`` that was ``given`` (on the command line, in a YAML
    step or by --set), whatever its value: an option with no effect in this run is refused,
    never silently ignored, also when it repeats the default (which a reader cannot tell from
    one that would matter, e.g. ``--g 2:8`` against ``--g=2:8.0``); and not recorded
    (:func:`unused_in`)."""
    declared = {p.name: p for p in params}
    noted = _NOTED.get()
    if noted is not None:
        noted.update(names)
    for name in names:
        if name in given:
            raise OptionError(f"{declared[name].label} {reason}")


_NOTED: contextvars.ContextVar[set | None] = contextvars.ContextVar("plenocli_noted",
                                                                   default=None)


def unused_in(check, values: Mapping[str, Any]) -> frozenset:
    """The parameters a schema's ``check`` finds without effect for ``values`` (the names it
    hands to :func:`refuse_unused`)."""
    noted: set = set()
    token = _NOTED.set(noted)
    try:
        check(values, ())  # nothing given: every check passes, and names what it would refuse
    finally:
        _NOTED.reset(token)
    return frozenset(noted)
