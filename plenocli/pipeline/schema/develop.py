"""Parameters of ``plenocli develop``."""

import os
from collections.abc import Collection

from plenocli.errors import OptionError
from plenocli.model.colour import DEFAULT_METHOD, MAX_GAIN_RATIO, METHODS, OUTPUT_SPACES
from plenocli.model.numbers import decimal
from plenocli.pipeline.params import PREVIEW, Param, input_arg, refuse_unused
from plenocli.pipeline.validators import (
    TIFF,
    Choice,
    FiniteFloat,
    InputFile,
    Int,
    OutputFile,
    Text,
)


class WhiteBalance(Text):
    """``as-shot`` or three positive finite gains ``R,G,B``."""

    name = "as-shot|R,G,B"

    def convert(self, value) -> str:
        text = super().convert(value).strip()
        if text == "as-shot":
            return text
        try:
            gains = [decimal(p) for p in text.split(",")]
        except ValueError:
            gains = []
        if len(gains) != 3 or not all(0 < g < float("inf") for g in gains):
            raise ValueError(f"{text!r}: give as-shot or three positive gains R,G,B (e.g. "
                             "2.1,1,1.6)")
        if max(gains) > MAX_GAIN_RATIO * min(gains):
            raise ValueError(f"{text!r}: one gain is more than {MAX_GAIN_RATIO:g} times another; "
                             "white-balance gains are within a few times each other (e.g. "
                             "2.1,1,1.6)")
        return ",".join(repr(g) for g in gains)


# the photograph's formats by name (io/photo.FORMATS, which writes them)
PHOTO_SUFFIXES = (".tif", ".tiff", ".jpg", ".jpeg", ".png")

PARAMS = (
    input_arg(),
    Param("output", OutputFile(*PHOTO_SUFFIXES, formats="a 16-bit TIFF, an 8-bit JPEG or PNG"),
          "The photograph (written atomically): a 16-bit TIFF, an 8-bit JPEG or PNG, by the "
          "name's suffix.", role="output", flags=("-o", "--output"), required=True),
    Param("view", Text(), "Which view to develop (e.g. S); needed when the file holds several."),
    Param("method", Choice(METHODS), "Demosaicing method (docs/colour.md compares them).",
          default=DEFAULT_METHOD),
    Param("wb", WhiteBalance(), "White balance: the raw's as-shot gains, or R,G,B multipliers.",
          default="as-shot"),
    Param("wb_from", InputFile(), "White balance measured on a white image (its decode, bias or "
          "flat TIFF: decode's black levels are taken off).", role="input"),
    Param("matrix", Choice(["as-shot", "none"]), "Camera colour matrix from the raw, or none "
          "(camera RGB taken as sRGB).", default="as-shot"),
    Param("space", Choice(OUTPUT_SPACES), "Output colour space (its ICC profile is embedded).",
          default="srgb"),
    Param("exposure", FiniteFloat(min=-10, max=10), "Exposure (EV) on top of the automatic white "
          "point (99th percentile = 1).", default=0.0),
    Param("quality", Int(1, 100), "JPEG quality.", default=95),
    Param("recover_highlights", InputFile(), "Dual-pixel: rebuild S (and B) from A where only S "
          "clipped, with the A/S split of this white image (views A, B, S, processed like "
          "INPUT).", role="input"),
    Param("linear", OutputFile(*TIFF), "Also write the scene-referred linear sRGB as a float32 "
          "TIFF (R, G, B pages).", role="output"),
    PREVIEW,
)


def shared_inputs(params) -> tuple[tuple[str, str], ...]:
    """One white image may give both the white balance and the highlight recovery."""
    return (("wb_from", "recover_highlights"),)


def check(params: dict, given: Collection[str]) -> None:
    """A measured white balance replaces --wb, only a JPEG has a quality, linear Rec.2020
    needs a 16-bit TIFF, and only mosaiced views have a demosaicing method."""
    if params.get("wb_from"):
        refuse_unused(PARAMS, given, ["wb"], "and --wb-from both set the white balance; give one")
    suffix = os.path.splitext(str(params.get("output", "")))[1].lower()
    if suffix not in (".jpg", ".jpeg"):
        refuse_unused(PARAMS, given, ["quality"], "applies to a JPEG output (-o NAME.jpg) only")
    if params.get("space") == "rec2020-linear" and suffix not in TIFF:
        # an 8-bit JPEG or PNG bands a linear encoding: a clash of two options, as --quality's
        raise OptionError(f"--space rec2020-linear needs 16 bits: write -o NAME.tif, or choose "
                          f"--space srgb or display-p3 for {suffix[1:].upper() or 'this'} output")
    meta = _views_meta(params.get("input"))
    if meta is not None and not _mosaiced(meta):
        refuse_unused(PARAMS, given, ["method"], "applies to mosaiced (Bayer) views only: "
                      "INPUT's views carry no colour filter pattern (colour pages, demosaiced "
                      "already, or grey)")


def recorded(params: dict) -> dict:
    """The view developed, where INPUT holds one colour view and none was named (a panorama's
    R, G, B pages are view RGB): the record says which, as the photograph's provenance does."""
    from plenocli.colour.develop import colour_views

    meta = _views_meta(params.get("input"))
    if params.get("view") is not None or meta is None:
        return {}
    try:
        views = colour_views(list(meta["views"]), cfa=meta.get("cfa"),
                             view_colours=meta.get("view_colours"))
    except ValueError:
        return {}
    return {"view": views[0].name} if len(views) == 1 else {}


def _views_meta(path) -> dict | None:
    """INPUT's plenocli metadata when it names its views; None when the file is not there yet
    (a step of a run that makes it) or says nothing (the stage then refuses it itself)."""
    from plenocli.errors import PlenocliError
    from plenocli.io.tiffio import read_meta

    if not path or not os.path.isfile(path):
        return None
    try:
        meta = read_meta(path)
    except (PlenocliError, OSError, ValueError):
        return None
    return meta if meta.get("views") else None


def _mosaiced(meta: dict) -> bool:
    """Whether the views are mosaics develop demosaics (a CFA for the file or per view)."""
    return bool(meta.get("cfa")) or any(c is not None for c in meta.get("view_colours") or [])
