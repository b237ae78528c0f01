"""Stage ``simulate``: a synthetic capture set of one KIND (raws + ground truth) into a folder.

The generators in :mod:`plenocli.synth` return the files as arrays (a
:class:`~plenocli.synth.capture.Simulation`); :mod:`plenocli.io.simfiles` writes them and
``truth.json`` with the provenance, together or not at all.
"""

from __future__ import annotations

import os

from plenocli.errors import ConfigError, OptionError
from plenocli.io.simfiles import write_simulation
from plenocli.model.provenance import stage_record
from plenocli.pipeline.schema.simulate import generator_kwargs
from plenocli.progress import log, shown


def run(kind: str, output: str, *, seed: int = 0, pixels: str | None = None,
        rays: int | None = None, no_prisms: bool = False, param: tuple[str, ...] = ()) -> None:
    """Write the capture set of ``kind`` into the folder ``output``.

    ``pixels`` (one number or ROWSxCOLS), ``rays`` and ``no_prisms`` go to the kinds that take
    them; ``param`` holds more keyword options as ``KEY=VALUE`` strings (YAML values).
    """
    kwargs = generator_kwargs(dict(seed=seed, pixels=pixels, rays=rays, no_prisms=no_prisms,
                                   param=param))
    simulate(kind, output, **kwargs)
    log.info("simulate %s: wrote %s", kind, shown(output))


def simulate(kind: str, output: str | os.PathLike, **params) -> dict:
    """Generate the capture set of ``kind`` with ``params`` and write it into ``output``.

    Returns the truth as written to ``truth.json`` (with its ``provenance``).
    """
    from plenocli.synth import KIND_NAMES, generator
    from plenocli.synth.params import check_params, resolved_params

    if kind not in KIND_NAMES:
        raise ConfigError(f"simulate: unknown kind {kind!r}; use one of {', '.join(KIND_NAMES)}")
    generate = generator(kind)
    try:
        params = check_params(kind, generate, params)
    except ValueError as err:
        raise OptionError(str(err)) from err
    try:
        sim = generate(**params)
    except (ValueError, TypeError) as err:  # parameters that do not go together
        raise OptionError(f"simulate {kind}: {err}") from err
    # the kind's defaults too: every output records its fully resolved parameters
    record = stage_record("simulate", {"kind": kind, **resolved_params(generate, params)}, {})
    truth = {**sim.truth, "provenance": record}
    write_simulation(output, sim.files, truth, record)
    return truth

