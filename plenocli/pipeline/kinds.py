"""Which kind of file each stage takes for each input role, read from the producing stage.

Every plenocli TIFF records the stage that made it (``provenance.stage``, and the stages
before it in ``history``), so a stage can refuse a file of the wrong kind (a depth map as
views, a gain map as a white) or one it has already processed (unmix of an unmixed file,
flat of a flat-fielded one): both would give a wrong result with exit 0. Foreign files (no
plenocli record) are accepted as they are: their reader checks what it can.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from plenocli.errors import InputError
from plenocli.pipeline.validators import TIFF

# frames or views of one capture, as decode, bias, flat and unmix leave them (and the simulator)
CAPTURE = ("decode", "bias", "flat", "unmix", "simulate")
# views of a capture: also the SAIs sai cuts and the (stereo) views refocus renders
VIEWS = (*CAPTURE, "sai", "refocus")
PICTURES = (*VIEWS, "stitch", "develop")

# stage -> input role -> the producing stages it accepts
ACCEPTS: dict[str, dict[str, tuple[str, ...]]] = {
    "bias": {"input": ("decode",)},
    "flat": {"input": CAPTURE, "white": ("decode", "bias", "simulate")},   # --gain: flat's own
    "unmix": {"inputs": VIEWS, "mixing": ("crosstalk", "simulate")},
    "crosstalk": {"inputs": VIEWS},
    "calibrate": {"input": CAPTURE},
    "sai": {"input": CAPTURE},
    "refocus": {"input": CAPTURE, "depth": ("depth",)},
    "depth": {"input": (*CAPTURE, "sai")},
    "develop": {"input": PICTURES, "wb_from": CAPTURE, "recover_highlights": CAPTURE},
    "stitch": {"inputs": VIEWS},
}
# stages that read what only their producer records (bias: decode's areas and levels)
RECORD_NEEDED = ("bias",)
# stages a capture goes through once: applied again they correct what is already corrected
ONCE = ("bias", "flat", "unmix")


def check_kinds(stage: str, inputs: Mapping[str, Sequence[Path]]) -> None:
    """InputError for the first input whose recorded producer ``stage`` does not take in its
    role, or that already went through ``stage`` (one of ONCE)."""
    from plenocli.io import tiffio

    for role, accepted in ACCEPTS.get(stage, {}).items():
        for path in inputs.get(role, ()):
            if Path(path).suffix.lower() not in TIFF or not Path(path).is_file():
                continue
            try:
                meta = tiffio.read_meta(path)
            except InputError:
                continue   # the stage's reader says what is wrong with it
            made = [r.get("stage") for r in (*(meta.get("history") or []),
                                             meta.get("provenance") or {})
                    if isinstance(r, dict)]
            if not made or made[-1] is None:
                continue
            if made[-1] not in accepted:
                foreign = "" if stage in RECORD_NEEDED else " (or a foreign file)"
                raise InputError(f"{path} is a `plenocli {made[-1]}` output; {stage} takes as "
                                 f"{role.replace('_', '-')} the output of "
                                 f"{', '.join(accepted)}{foreign}")
            if stage in ONCE and role in ("input", "inputs") and stage in made:
                raise InputError(f"{path} already went through `plenocli {stage}`; applying "
                                 "it twice corrects what is already corrected: give the file "
                                 "from before it")
