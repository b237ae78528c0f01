"""The stage registry: every stage a config can name, with which parameters are files.

A stage is a plain function ``run(**params)`` in ``plenocli.pipeline.stages.<name>``; its keyword
names are the command's long option names (and positional argument names), so the CLI, YAML
configs and ``--set`` all speak the same words. ``inputs`` and ``outputs`` name the parameters that
are file paths, which is what the make-style runner needs.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Stage:
    name: str
    run: Callable[..., Any]
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    def parameters(self) -> dict[str, Any]:
        """Parameter names and defaults (``inspect.Parameter.empty`` when required)."""
        return {n: p.default for n, p in inspect.signature(self.run).parameters.items()}


def _stages() -> dict[str, Stage]:
    from plenocli.pipeline.stages import (
        bias,
        calibrate,
        crosstalk,
        decode,
        flat,
        optics,
        refocus,
        sai,
        stitch,
    )

    table = [
        Stage("decode", decode.run, inputs=("input", "calib"), outputs=("output", "preview")),
        Stage("bias", bias.run, inputs=("input",), outputs=("output", "preview")),
        Stage("flat", flat.run, inputs=("input", "white", "gain"),
              outputs=("output", "save_gain", "preview")),
        Stage("calibrate", calibrate.run, inputs=("input", "compare", "start"),
              outputs=("output", "xml", "preview")),
        Stage("refocus", refocus.run, inputs=("input", "grid"), outputs=("output", "preview")),
        Stage("sai", sai.run, inputs=("input", "grid"), outputs=("output", "preview")),
        Stage("crosstalk", crosstalk.run, inputs=("inputs", "grid"),
              outputs=("output", "preview")),
        Stage("stitch", stitch.run, inputs=("inputs", "transform_in", "rig"),
              outputs=("output", "transform_out", "report", "preview")),
        Stage("optics", optics.run, inputs=("input",), outputs=("json",)),
    ]
    return {s.name: s for s in table}


def get_stages() -> dict[str, Stage]:
    """All registered stages by name."""
    return _stages()
