"""Stage ``flat``: vignetting correction with a gain map from a white image (or a saved gain)."""

from __future__ import annotations

import numpy as np

from plenocli.errors import InputError
from plenocli.flatfield import apply_gain, check_gains, white_gains
from plenocli.io import tiffio
from plenocli.io.preview import colour_pages, write_png
from plenocli.io.views import check_black_subtracted
from plenocli.model.provenance import stage_record
from plenocli.progress import log, shown

FLAT_WHY = "flat corrects bias-corrected views"


def run(input: str, output: str, *, white: str | None = None, gain: str | None = None,
        median: int = 5, reference: str = "max", percentile: float = 99.5, floor: float = 0.05,
        save_gain: str | None = None, preview: str | None = None) -> None:
    """Correct the views of ``input`` with a gain from ``white`` (or a saved ``gain`` file)."""
    views, meta = tiffio.read_image(input)
    check_black_subtracted(input, meta, FLAT_WHY)
    source = white if white is not None else gain
    ref, ref_meta = tiffio.read_image(source)
    if white is not None:
        check_black_subtracted(white, ref_meta, FLAT_WHY)
    _check_match(input, meta, views, source, ref_meta, ref)
    if white is not None:
        try:
            gains = white_gains(ref, names=ref_meta.get("views"), cfa=meta.get("cfa"),
                                median_px=median, reference=reference, percentile=percentile,
                                floor=floor)
        except ValueError as err:
            raise InputError(f"{white}: {err}") from err
    else:
        record = ref_meta.get("provenance", {})
        if record.get("stage") != "flat-gain":
            raise InputError(f"{gain}: not a gain map; make one with plenocli flat --save-gain")
        gains = ref.astype(np.float32, copy=False)
        made = record.get("parameters") if isinstance(record.get("parameters"), dict) else {}
        try:
            check_gains(gains, cfa=meta.get("cfa"), reference=made.get("reference"),
                        floor=made.get("floor"), names=ref_meta.get("views"))
        except (ValueError, TypeError) as err:
            raise InputError(f"{gain}: {err}; make the gain again with plenocli flat "
                             "--save-gain") from err
        tiffio.check_seal(gain, ref, ref_meta, "make the gain again with plenocli flat "
                          "--save-gain")
    corrected = apply_gain(views, gains)
    params = dict(median=median, reference=reference, percentile=percentile, floor=floor)
    inputs = {"input": input, "white": white, "gain": gain}
    record = stage_record("flat", params, inputs)
    masked = int(np.isnan(gains).any(axis=0).sum())
    tiffio.write_image(output, corrected, tiffio.derived_meta(meta, record, gain_masked=masked),
                       protect=(input, source))
    log.info("flat: %s -> %s (gain from %s, %s)", shown(input), shown(output), shown(source),
             _masked_words(masked, ref if white is not None else None, gains))
    if save_gain:
        gain_record = stage_record("flat-gain", params, {"white": source})
        gain_meta = tiffio.derived_meta(ref_meta, gain_record)
        tiffio.write_image(save_gain, gains, gain_meta, protect=(input, source), seal=True)
    if preview:
        rgb = colour_pages(corrected, meta.get("views"))  # R, G, B pages: one colour picture
        write_png(preview, corrected[:2] if rgb is None else rgb, cfa=meta.get("cfa"),
                  protect=(input, source), colour=meta.get("colour"))


def _check_match(path, meta, views, ref_path, ref_meta, ref) -> None:
    """The white image (or gain) must be the same geometry, CFA and views as the frames."""
    what = "white image" if ref_meta.get("provenance", {}).get("stage") != "flat-gain" else "gain"
    if ref.shape[1:] != views.shape[1:]:
        raise InputError(f"{ref_path}: {what} is {ref.shape[2]}x{ref.shape[1]} but {path} is "
                         f"{views.shape[2]}x{views.shape[1]}; use a {what} processed with the "
                         "same bias/crop settings")
    if ref_meta.get("cfa") != meta.get("cfa"):
        for file, cfa, other, other_cfa in ((path, meta.get("cfa"), ref_path, ref_meta.get("cfa")),
                                            (ref_path, ref_meta.get("cfa"), path, meta.get("cfa"))):
            if cfa is None:  # the file without one is the odd one: no or damaged plenocli metadata
                raise InputError(f"{file}: no CFA in its plenocli metadata (not a plenocli TIFF, "
                                 f"or its description was lost) but {other} has {other_cfa}; "
                                 "use the output of plenocli bias")
        raise InputError(f"{ref_path}: {what} has CFA {ref_meta.get('cfa')} but {path} has "
                         f"{meta.get('cfa')}; they must come from the same sensor and crop")
    if ref_meta.get("origin", [0, 0]) != meta.get("origin", [0, 0]):
        raise InputError(f"{ref_path}: {what} crop origin {ref_meta.get('origin')} differs from "
                         f"{path}'s {meta.get('origin')}; crop both the same way")
    names, ref_names = meta.get("views"), ref_meta.get("views")
    if ref.shape[0] != views.shape[0] or (names and ref_names and names != ref_names):
        raise InputError(f"{ref_path}: {what} views {ref_names} do not match {path}'s {names}")


def _masked_words(masked: int, white: np.ndarray | None, gains: np.ndarray) -> str:
    """How many pixels the gain masks, and why: NaN in the white itself (clipped, or masked by
    an earlier stage) or below the floor; a saved gain's count is only its own."""
    if white is None:
        return f"{masked} pixels masked in the gain"
    holes = int((np.isnan(white).any(axis=0) & np.isnan(gains).any(axis=0)).sum())
    return (f"{masked} pixels masked: {holes} NaN in the white, {masked - holes} below the "
            "floor")
