"""Stage ``simulate``: a synthetic capture set of one KIND (raws + ground truth) into a folder.

The generators in :mod:`plenocli.synth` return the files as arrays (a
:class:`~plenocli.synth.capture.Simulation`); this stage writes each one with its writer,
atomically, and ``truth.json`` with the provenance. The files land together or not at all: when
one write fails, the ones already written by this run are removed.
"""

from __future__ import annotations

import inspect
import json
import math
import os
from pathlib import Path

import numpy as np

from plenocli.errors import ConfigError
from plenocli.io.atomic import outputs_together
from plenocli.model.provenance import json_safe, stage_record
from plenocli.progress import log, shown

TRUTH_FILE = "truth.json"
MAX_PIXELS = 2 ** 27  # a 134 Mpx sensor: beyond every camera simulated here
MAX_RAYS = 2 ** 31    # rays traced in all: hours of work, gigabytes of arrays


def run(kind: str, output: str, *, seed: int = 0, pixels: str | int | None = None,
        rays: int | None = None, no_prisms: bool | None = None,
        param: tuple[str, ...] = ()) -> None:
    """Write the capture set of ``kind`` into the folder ``output``.

    ``pixels`` (one number or ROWSxCOLS), ``rays`` and ``no_prisms`` go to the kinds that take
    them; ``param`` holds more keyword options as ``KEY=VALUE`` strings (YAML values).
    """
    import yaml

    kwargs: dict = {"seed": seed}
    for key, value in (("pixels", pixels), ("rays", rays), ("no_prisms", no_prisms)):
        if value is not None:
            kwargs[key] = value
    if isinstance(kwargs.get("pixels"), str) and kwargs["pixels"].strip().isdigit():
        kwargs["pixels"] = int(kwargs["pixels"])  # one number, else ROWSxCOLS
    if kwargs.get("pixels") == 0:
        raise ConfigError("--pixels 0: give a sensor size, ROWSxCOLS or one number")
    for item in param:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--param {item!r}: expected KEY=VALUE")
        kwargs[key.strip().replace("-", "_")] = yaml.safe_load(value)
    simulate(kind, output, **kwargs)
    log.info("simulate %s: wrote %s", kind, shown(output))


def simulate(kind: str, output: str | os.PathLike, **params) -> dict:
    """Generate the capture set of ``kind`` with ``params`` and write it into ``output``.

    Returns the truth as written to ``truth.json`` (with its ``provenance``).
    """
    from plenocli.synth import KIND_NAMES, generator

    if kind not in KIND_NAMES:
        raise ConfigError(f"simulate: unknown kind {kind!r}; use one of {', '.join(KIND_NAMES)}")
    generate = generator(kind)
    accepted = inspect.signature(generate).parameters
    for key, value in params.items():
        if key not in accepted:
            raise ConfigError(f"simulate {kind} does not take {key!r}; it takes: "
                              f"{', '.join(accepted)}")
        _check_value(kind, key, value, accepted[key].default)
    _check_size(kind, params)
    try:
        sim = generate(**params)
    except (ValueError, TypeError) as err:
        raise ConfigError(f"simulate {kind}: {err}") from err
    record = stage_record("simulate", {"kind": kind, **params}, {})
    truth = {**sim.truth, "provenance": record}
    write_simulation(output, sim.files, truth, record)
    return truth


def _check_size(kind: str, params: dict) -> None:
    """Refuse, before any allocation, a sensor or a ray count no machine simulates."""
    rows, cols = _sensor_shape(params)
    rays = params["rays"] if isinstance(params.get("rays"), int) else 1
    if rows * cols > MAX_PIXELS or rows * cols * rays > MAX_RAYS:
        raise ConfigError(f"simulate {kind}: {rows} x {cols} pixels x {rays} rays is beyond what "
                          f"a simulation holds ({MAX_PIXELS:.3g} pixels, {MAX_RAYS:.3g} rays); "
                          "simulate a smaller sensor")


def _sensor_shape(params: dict) -> tuple[int, int]:
    """(rows, cols) the parameters ask for, as far as they say (1 for what they leave out)."""
    pixels = params.get("pixels")
    if isinstance(pixels, int):
        return pixels, pixels
    parts = str(pixels).lower().split("x")
    if len(parts) == 2 and all(p.strip().isdigit() for p in parts):
        return int(parts[0]), int(parts[1])
    if isinstance(params.get("size"), int):
        return params["size"], params["size"]
    shape = params.get("view_shape")
    if isinstance(shape, (list, tuple)) and len(shape) == 2 and all(
            isinstance(v, int) for v in shape):
        return shape[0], shape[1]
    rows, cols = params.get("rows"), params.get("cols")
    return rows if isinstance(rows, int) else 1, cols if isinstance(cols, int) else 1


def _check_value(kind: str, key: str, value, default) -> None:
    """A value of the type the kind's default has (a whole number where the default is one,
    a list of as many numbers as the default's), every number finite: ConfigError otherwise."""
    def number(v, whole: bool) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return False
        return math.isfinite(v) and (isinstance(v, int) or not whole)

    if default is None or default is inspect.Parameter.empty:
        ok = not isinstance(value, float) or math.isfinite(value)
    elif isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, (int, float)):
        ok = number(value, whole=isinstance(default, int))
    elif isinstance(default, (tuple, list)):
        ok = (isinstance(value, (tuple, list)) and len(value) == len(default)
              and all(number(v, whole=isinstance(d, int))
                      for v, d in zip(value, default, strict=True)))
    else:
        ok = isinstance(value, type(default))
    if not ok:
        shown_default = list(default) if isinstance(default, tuple) else default
        raise ConfigError(f"simulate {kind}: {key} = {value!r} is not a value like its default "
                          f"{shown_default!r} (finite numbers; whole where the default is)")


def write_simulation(output: str | os.PathLike, files, truth: dict, record: dict) -> None:
    """Write ``files`` (SimFile) and ``truth.json`` into the folder ``output`` (created when
    missing); nothing of this run is left behind when a write fails."""
    out = Path(output)
    with outputs_together():
        for item in files:
            _write_file(out / item.name, item, record)
        _write_truth(out / TRUTH_FILE, truth)


def _write_truth(path: Path, truth: dict) -> None:
    from plenocli.io.atomic import write_text

    write_text(path, json.dumps(json_safe(truth), indent=1, allow_nan=False) + "\n")


def _write_file(path: Path, item, record: dict) -> None:
    """One SimFile with the writer its format names."""
    from plenocli.io import tiffio
    from plenocli.io.atomic import atomic_path

    if item.format == "tiff":
        import tifffile

        with atomic_path(path) as tmp:
            tifffile.imwrite(tmp, item.data, photometric=item.options["photometric"])
    elif item.format == "image":
        tiffio.write_image(path, item.data, tiffio.derived_meta(item.options["meta"], record))
    elif item.format == "dng":
        from plenocli.io.dng import write_dng

        write_dng(path, item.data, **item.options)
    elif item.format == "npz":
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, **item.data)
    elif item.format == "grid":
        from plenocli.io.gridfile import write_grid

        write_grid(path, item.data, record)
    else:  # raytrix-xml
        from plenocli.io import raytrix

        raytrix.write_calib(path, raytrix.calib_from_grid(item.data))


def write_dualpixel_raw(path: str | os.PathLike, raw: np.ndarray, truth: dict) -> None:
    """Write a capture of :func:`plenocli.synth.dualpixel.dualpixel_capture` as its two-frame
    DNG (frames S, A), e.g. for a test fixture."""
    from plenocli.io.dng import write_dng
    from plenocli.synth.dualpixel import dng_options

    write_dng(path, raw, **dng_options(truth))
