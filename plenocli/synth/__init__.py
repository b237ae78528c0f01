"""Synthetic captures with ground truth, made by one generator package.

Every generator is a pure function of its parameters and a seed (``np.random.default_rng``) and
returns arrays plus a truth dict. ``generator(KIND)`` is the function ``plenocli simulate KIND``
calls: it returns a :class:`plenocli.synth.capture.Simulation` (the files of a capture set, in
memory, and its truth), which the ``simulate`` stage writes. ``KIND_NAMES`` lists the kinds
without importing any generator (the CLI's help stays fast), and ``generator`` imports only the
module of the kind asked for.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from functools import partial

# kind -> (module in plenocli.synth, function, keywords fixed by the kind)
_SOURCES: dict[str, tuple[str, str, dict]] = {
    "dualpixel": ("dualpixel", "simulate_capture_set", {}),
    "raytrix-scene": ("focused", "simulate_raytrix_scene", {}),
    "lenslet-depth": ("depthscene", "simulate_lenslet_depth", {}),
    "dualpixel-depth": ("depthscene", "simulate_disparity", {}),
    "quadpixel-depth": ("depthscene", "simulate_disparity", {"quad": True}),
    "hexgrid-white": ("whiteimage", "simulate_hexgrid_white", {}),
    "quadpixel-pyramid": ("prismsets", "simulate_quadpixel", {}),
    "quadpixel-white": ("prismsets", "simulate_quadpixel", {"scene": "white", "no_prisms": True}),
    "quadpixel-masked": ("prismsets", "simulate_quadpixel",
                         {"scene": "white", "open_quarters": "00"}),
    "dualpixel-prism": ("prismsets", "simulate_dualpixel", {}),
    "dualpixel-white": ("prismsets", "simulate_dualpixel", {"scene": "white", "no_prisms": True}),
    "dualpixel-masked": ("prismsets", "simulate_dualpixel", {"scene": "white",
                                                             "open_halves": "A"}),
    "raytrix-prism": ("prismsets", "simulate_raytrix", {}),
    "raytrix-white": ("prismsets", "simulate_raytrix", {"scene": "white", "no_prisms": True}),
    "stereo-rig": ("rig", "simulate_stereo_rig", {}),
    "quad-rig": ("rig", "simulate_quad_rig", {}),
    "dualpixel-ghost": ("mixing", "simulate_dualpixel_ghost", {}),
    "quadpixel-ghost": ("mixing", "simulate_quadpixel_ghost", {}),
    "quadpixel-ghost-mask": ("mixing", "simulate_quadpixel_ghost", {"cross_mask": True}),
    "raytrix-ghost": ("mixing", "simulate_raytrix_ghost", {}),
}
KIND_NAMES = tuple(sorted(_SOURCES))


def generator(kind: str) -> Callable[..., object]:
    """The generator of ``kind``: ``generate(*, seed, ...) -> Simulation``."""
    if kind not in _SOURCES:
        raise ValueError(f"kind must be one of {', '.join(KIND_NAMES)}, got {kind!r}")
    module, name, fixed = _SOURCES[kind]
    func = getattr(importlib.import_module(f"plenocli.synth.{module}"), name)
    return partial(func, **fixed) if fixed else func


def kinds() -> dict[str, Callable[..., object]]:
    """Every kind's generator by name (imports every generator module)."""
    return {kind: generator(kind) for kind in KIND_NAMES}
