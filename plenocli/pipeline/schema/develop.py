"""Parameters of ``plenocli develop``."""

import os
from collections.abc import Collection

from plenocli.errors import OptionError
from plenocli.model.colour import DEFAULT_METHOD, MAX_GAIN_RATIO, METHODS, OUTPUT_SPACES
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
            gains = [float(p) for p in text.split(",")]
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
    Param("wb_from", InputFile(), "White balance measured on a white image (bias-corrected views "
          "TIFF).", role="input"),
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
    """A measured white balance replaces --wb, only a JPEG has a quality, and linear Rec.2020
    needs a 16-bit TIFF."""
    if params.get("wb_from"):
        refuse_unused(PARAMS, given, ["wb"], "and --wb-from both set the white balance; give one")
    suffix = os.path.splitext(str(params.get("output", "")))[1].lower()
    if suffix not in (".jpg", ".jpeg"):
        refuse_unused(PARAMS, given, ["quality"], "applies to a JPEG output (-o NAME.jpg) only")
    if params.get("space") == "rec2020-linear" and suffix not in TIFF:
        # an 8-bit JPEG or PNG bands a linear encoding: a clash of two options, as --quality's
        raise OptionError(f"--space rec2020-linear needs 16 bits: write -o NAME.tif, or choose "
                          f"--space srgb or display-p3 for {suffix[1:].upper() or 'this'} output")
