"""Parameters of ``plenocli crosstalk``."""

from collections.abc import Collection

from plenocli.errors import OptionError
from plenocli.model.focus import MAX_S
from plenocli.model.numbers import number_word
from plenocli.pipeline.params import PREVIEW, Param, inputs_arg, output_param, refuse_unused
from plenocli.pipeline.validators import (
    TIFF,
    FiniteFloat,
    InputFile,
    Int,
    NameList,
    OutputFile,
    Validator,
    ViewList,
    shell_text,
)


class MaskWidths(Validator):
    """W,W,...: the mask widths of the sweep, checked by the stage's own parser (kept as its
    resolved text: ' 0, 1.0 ' is 0,1)."""

    name = "W,W,..."

    def convert(self, value) -> str:
        from plenocli.pipeline.stages.crosstalk import parse_mask_widths

        return ",".join(number_word(w) for w in parse_mask_widths(shell_text(value)))


PARAMS = (
    inputs_arg(),
    output_param(".json"),
    Param("views", ViewList(), "Views to compare, by name or page number, e.g. A,B (leaves out the "
          "sum view S that bias writes); default: all pages."),
    Param("intended", NameList(), "Name of the view whose pupil part was open (one, or one per "
          "input, comma separated); default: the brightest view. With --mask-widths: "
          "left|right."),
    Param("tile", Int(min=2, parity="even"), "Tile side (px, even) of the cross-talk map.",
          default=64),
    PREVIEW,
    Param("mask_widths", MaskWidths(), "Raytrix sweep: mask widths m (px), e.g. 0,1,2,3, each "
          "below the lens pitch; INPUT is then a frames TIFF and --grid is needed (uses "
          "plenocli refocus)."),
    Param("grid", InputFile(), "Lens grid YAML (only with --mask-widths).", role="input"),
    Param("s", FiniteFloat(min=0, max=MAX_S, min_open=True),
          "Refocus scale s (only with --mask-widths).", default=0.2),
    Param("g", FiniteFloat(min=0, min_open=True), "Refocus g (only with --mask-widths).",
          default=4.0),
    Param("mixing_out", OutputFile(*TIFF), "Also write the mixing-matrix field M (TIFF) for "
          "plenocli unmix; needs one masked white per pupil part (with --intended naming each "
          "one's open part).", role="output"),
)


def check(params: dict, given: Collection[str]) -> None:
    """The refocus options of the mask sweep are refused without it, not ignored; the views
    options and the mixing with it (the sweep refocuses its own left and right views)."""
    if not params.get("mask_widths"):
        refuse_unused(PARAMS, given, ["s", "g", "grid"],
                      "applies to the --mask-widths sweep only")
        named = [n.strip() for n in (params.get("views") or "").split(",") if n.strip()]
        if len(named) == 1:
            raise OptionError(f"--views names one view ({named[0]}): cross-talk compares two "
                              "or more; name them all, e.g. --views A,B")
    else:
        refuse_unused(PARAMS, given, ["views", "mixing_out"],
                      "does not apply to the --mask-widths sweep (it refocuses its own left and "
                      "right views); measure the mixing on refocused views of masked whites")
        refuse_unused(PARAMS, given, ["preview"],
                      "is not drawn for the --mask-widths sweep (its r per mask width is in the "
                      "JSON report); leave it out")
        if not params.get("grid"):
            raise OptionError("--mask-widths needs --grid: the lens grid of the capture (YAML "
                              "from plenocli calibrate, or the camera's RayCalibData XML)")
