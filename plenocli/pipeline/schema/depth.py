"""Parameters of ``plenocli depth``."""

from collections.abc import Collection

from plenocli.depth import MAX_DISPARITY
from plenocli.model.focus import MAX_S
from plenocli.model.numbers import number_word
from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, input_arg, refuse_unused
from plenocli.pipeline.validators import FiniteFloat, InputFile, Validator, shell_text


class GRange(Validator):
    """MIN:MAX of the g search, checked by the stage's own parser (kept as its resolved text)."""

    name = "MIN:MAX"

    def convert(self, value) -> str:
        from plenocli.pipeline.stages.depth import parse_range

        lo, hi = parse_range(shell_text(value))
        # as resolved: ' 2 : 8 ' is 2:8; every digit kept (:g would make 2.1234567 2.12346)
        return f"{number_word(lo)}:{number_word(hi)}"


PARAMS = (
    input_arg(),
    OUTPUT,
    Param("grid", InputFile(), "Lens grid (YAML or RayCalibData XML): INPUT is lenslet frames. "
          "Without it INPUT holds dual-pixel views A, B or quad-pixel SAIs S00..S11.",
          role="input"),
    Param("s", FiniteFloat(min=0, max=MAX_S, min_open=True),
          "Output grid of `plenocli refocus --s S` (lenslet).", default=0.2),
    Param("g", GRange(), "Search range of g (lenslet); Galilean cameras: negative, e.g. -8:-2.",
          default="2:8"),
    Param("min_confidence", FiniteFloat(0, 1),
          "Lenses below this confidence leave g unknown (NaN).", default=0.1),
    Param("max_disparity", FiniteFloat(0.5, MAX_DISPARITY),
          "Largest |disparity| searched (px, dual/quad-pixel).", default=4.0),
    Param("camera", InputFile(), "Camera YAML (focal_length_mm, focus_distance_m, mla_sensor_mm):"
          " adds a depth_m page (lenslet).", role="input"),
    PREVIEW,
)


def check(params: dict, given: Collection[str]) -> None:
    """Options of the other kind of input are refused, not ignored."""
    if params.get("grid"):
        refuse_unused(PARAMS, given, ["max_disparity"],
                      "applies to dual/quad-pixel views (without --grid) only")
    else:
        refuse_unused(PARAMS, given, ["s", "g", "min_confidence", "camera"],
                      "applies to lenslet frames (with --grid) only")
