"""A prism rig file (``--rig RIG.yaml``): YAML or JSON with the keys of
:meth:`plenocli.model.rig.PrismRig.to_dict` (or a ``rig`` key holding them, e.g. a stitch
report), checked as the rig is made (known keys, numbers, a glass's index, an aperture of at
most f/0.5, pupil and prism sides of -1, 0 or 1, no two views alike). Ready-made rigs:
configs/rigs/."""

from __future__ import annotations

from pathlib import Path

from plenocli.errors import InputError
from plenocli.io.yamlfile import read_side_file
from plenocli.model.rig import PrismRig


def read_rig(path: str | Path) -> PrismRig:
    """The rig of a file, refused in one line naming the file and the key otherwise."""
    data = read_side_file(path, "YAML rig", hint="see configs/rigs/ for examples")
    if isinstance(data, dict) and isinstance(data.get("rig"), dict):
        data = data["rig"]  # a stitch report: the rig it used
    elif isinstance(data, dict) and isinstance(data.get("transform"), dict):
        raise InputError(f"{path} is a stitch transform (saved by --transform-out), not a rig: "
                         "pass it with --transform-in")
    try:
        return PrismRig.from_dict(data)
    except ValueError as err:
        raise InputError(f"{path}: {err}; see configs/rigs/ for examples") from err
