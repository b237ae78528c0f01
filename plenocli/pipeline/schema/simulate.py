"""Parameters of ``plenocli simulate``; the generator's own (``--param KEY=VALUE``) are declared
in :mod:`plenocli.synth.params` and checked by :func:`check`, for the shell and a YAML step."""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

from plenocli.errors import OptionError
from plenocli.pipeline.params import Param
from plenocli.pipeline.validators import Choice, Flag, Int, OutputFolder, SensorSize, Validator
from plenocli.synth import KIND_NAMES


class KeyValue(Validator):
    """``KEY=VALUE``, the value read as YAML (kept as that text, resolved as the generator
    reads it: ``' noise-x = 0 '`` is ``noise_x=0``)."""

    name = "KEY=VALUE"

    def convert(self, value: Any) -> str:
        text = super().convert(value)
        key, sep, rest = text.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"{text!r}: expected KEY=VALUE, e.g. noise=0")
        return f"{key.strip().replace('-', '_')}={rest.strip()}"


PARAMS = (
    Param("kind", Choice(KIND_NAMES), role="value", positional=True, required=True,
          metavar="KIND"),
    Param("output", OutputFolder(), "Folder for the capture files and truth.json.",
          role="folder", flags=("-o", "--output"), required=True),
    Param("seed", Int(min=0), "Random seed.", default=0),
    Param("pixels", SensorSize(), "Sensor size: one number (a square sensor), or ROWSxCOLS for the "
          "kinds that take it (dualpixel and the -depth kinds)."),
    Param("rays", Int(min=1), "Rays per pixel (optical kinds)."),
    Param("no_prisms", Flag(), "Remove the prisms (optical kinds)."),
    Param("param", KeyValue(), "Another option of the kind (repeatable), e.g. --param noise=0.",
          multiple=True, metavar="KEY=VALUE"),
)

OWN_OPTIONS = tuple(p.name for p in PARAMS if p.name not in ("kind", "output", "param"))


def generator_kwargs(params: dict[str, Any]) -> dict[str, Any]:
    """The keyword arguments of the kind's generator that ``params`` ask for; a value given
    twice (a key repeated, or one that has its own option) is refused: one would be dropped."""
    from plenocli.io.yamlfile import DocumentError, comment_in, load_yaml
    from plenocli.synth.params import PARAMS as SYNTH_PARAMS

    kwargs: dict[str, Any] = {"seed": params["seed"]}
    pixels = params.get("pixels")
    if pixels is not None:  # one number, else ROWSxCOLS (SensorSize checked the form)
        kwargs["pixels"] = int(pixels) if str(pixels).isdigit() else pixels
    if params.get("rays") is not None:
        kwargs["rays"] = params["rays"]
    if params.get("no_prisms"):
        kwargs["no_prisms"] = True
    given: dict[str, Any] = {}
    for item in params.get("param", ()):
        key, _, value = item.partition("=")
        name = key.strip().replace("-", "_")
        if name in OWN_OPTIONS:
            raise OptionError(f"--param {item!r}: {name} has its own option; give "
                              f"--{name.replace('_', '-')} instead")
        if name in given:
            raise OptionError(f"--param {item!r}: {name} is given twice; keep one")
        if not value.strip():
            raise OptionError(f"--param {item!r}: no value after '='; give KEY=VALUE, "
                              "e.g. noise=0")
        if (comment := comment_in(value)) is not None:
            raise OptionError(f"--param {item!r}: YAML reads {comment!r} as a comment, not as "
                              "part of the value; quote the value to keep it")
        try:
            parsed = load_yaml(value)
            text = name in SYNTH_PARAMS and SYNTH_PARAMS[name].text
            kwargs[name] = given[name] = value.strip() if text and not isinstance(
                parsed, str) else parsed
        except DocumentError as err:
            raise OptionError(f"--param {item!r}: the value is not valid YAML ({err}); "
                              "quote it") from err
    return kwargs


def check(params: dict[str, Any], given: Collection[str]) -> None:
    """Every generator parameter known to the kind, of its type and in its declared range."""
    from plenocli.synth import generator
    from plenocli.synth.params import check_params

    kind = params["kind"]
    try:
        check_params(kind, generator(kind), generator_kwargs(params))
    except ValueError as err:  # a value the kind does not take: a usage error, as for a flag
        raise OptionError(str(err)) from err


def recorded(params: dict[str, Any]) -> dict[str, Any]:
    """The kind's generator parameters as the run resolves them, defaults included (every
    output records its fully resolved parameters): beside the command's own in the record."""
    from plenocli.synth import generator
    from plenocli.synth.params import resolved_params

    return {"kind_parameters": resolved_params(generator(params["kind"]),
                                               generator_kwargs(params))}
