"""What a simulation returns: the files of a capture set, as arrays and values, plus its truth.

The generators stay pure (arrays in memory); the ``simulate`` stage
(:mod:`plenocli.pipeline.stages.simulate`) writes every :class:`SimFile` with the writer its
``format`` names, atomically, and ``truth.json`` with the provenance.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

FORMATS = ("tiff", "image", "dng", "npz", "grid", "raytrix-xml")


@dataclass(frozen=True)
class SimFile:
    """One file of a capture set.

    ``format``: ``tiff`` (a plain TIFF of ``data``; ``options["photometric"]``), ``image`` (a
    plenocli TIFF; ``options["meta"]`` its metadata), ``dng`` (``options`` are
    :func:`plenocli.io.dng.write_dng` keywords), ``npz`` (``data`` a dict of arrays), ``grid``
    (``data`` a LensGrid, as YAML) or ``raytrix-xml`` (``data`` a LensGrid, as RayCalibData).
    """

    name: str
    data: Any
    format: str
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.format not in FORMATS:
            raise ValueError(f"file format must be one of {FORMATS}, got {self.format!r}")


@dataclass(frozen=True)
class Simulation:
    """A simulated capture set: its files and its ground truth (JSON-ready dict)."""

    files: tuple[SimFile, ...]
    truth: dict
