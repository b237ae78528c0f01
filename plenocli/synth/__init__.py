"""Synthetic captures with ground truth, made by one generator package.

Every generator is a pure function of its parameters and a seed (``np.random.default_rng``) and
returns arrays plus a truth dict; ``kinds()`` maps the names ``plenocli simulate KIND`` accepts to
functions returning a :class:`plenocli.synth.capture.Simulation` (the files of a capture set, in
memory, and its truth), which the ``simulate`` stage writes. ``KIND_NAMES`` lists those names
without importing any generator (the CLI's help stays fast).
"""

from __future__ import annotations

from collections.abc import Callable

KIND_NAMES = ("dualpixel", "dualpixel-masked", "dualpixel-prism", "dualpixel-white",
              "hexgrid-white", "quad-rig", "quadpixel-masked", "quadpixel-pyramid",
              "quadpixel-white", "raytrix-prism", "raytrix-scene", "raytrix-white", "stereo-rig")


def kinds() -> dict[str, Callable[..., object]]:
    """Simulation kinds by name: ``simulate(*, seed, ...) -> Simulation``."""
    from plenocli.synth import dualpixel, focused, prismsets, rig, whiteimage

    return {
        "dualpixel": dualpixel.simulate_capture_set,
        "raytrix-scene": focused.simulate_raytrix_scene,
        "hexgrid-white": whiteimage.simulate_hexgrid_white,
        **prismsets.kinds(),
        "stereo-rig": rig.simulate_stereo_rig,
        "quad-rig": rig.simulate_quad_rig,
    }
