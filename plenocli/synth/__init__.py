"""Synthetic captures with ground truth, made by one generator package.

Every generator is a pure function of its parameters and a seed (``np.random.default_rng``) and
returns arrays plus a ``truth`` dict; ``KINDS`` maps the names ``plenocli simulate KIND`` accepts
to functions that write a capture set (raws + ``truth.json``) into a folder.
"""

from __future__ import annotations

from collections.abc import Callable


def kinds() -> dict[str, Callable[..., dict]]:
    """Simulation kinds by name: ``write(out_dir, *, seed, size, ...) -> truth``."""
    from plenocli.synth import dualpixel, focused, mixing, prismcam, rig, whiteimage

    return {
        "dualpixel": dualpixel.write_capture_set,
        "raytrix-scene": focused.write_raytrix_scene,
        "hexgrid-white": whiteimage.write_hexgrid_white,
        **prismcam.kinds(),
        "stereo-rig": rig.write_stereo_rig,
        "quad-rig": rig.write_quad_rig,
        **mixing.kinds(),
    }
