"""Parameters of ``plenocli refocus``."""

from collections.abc import Collection

from plenocli.model.focus import KERNELS, MAX_S, VIEWS, g_words
from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, input_arg, refuse_unused
from plenocli.pipeline.validators import Choice, FiniteFloat, InputFile, Validator, shell_text


class GValues(Validator):
    """One g, a list 2,3,4 or a range 2:6:0.5, checked by the library's own parser and kept
    as its resolved text (the stage parses it again; records compare it)."""

    name = "G"

    def convert(self, value) -> str:
        return g_words(shell_text(value))


PARAMS = (
    input_arg(),
    OUTPUT,
    Param("grid", InputFile(), "Lens grid (plenocli YAML from `plenocli calibrate`).",
          role="input", required=True),
    Param("s", FiniteFloat(min=0, max=MAX_S, min_open=True),
          "Size of the refocused image relative to the sensor image.", default=0.2),
    Param("g", GValues(), "Refocus parameter (negative for a Galilean camera); a list (2,3,4) "
          "or range (2:6:0.5, stop included) makes a focal sweep: one page per g and a "
          "sharpness score per g.", default="4"),
    Param("view", Choice(VIEWS), "Pupil mask: the whole micro-image, a half or a quadrant.",
          default="full"),
    Param("mask_width", FiniteFloat(min=0),
          "Width m (px) of the central band left out of half views.", default=2.0),
    Param("kernel", Choice(KERNELS),
          "Splatting kernel.", default="lanczos3"),
    Param("radius", FiniteFloat(min=0, min_open=True),
          "Use only pixels within this distance (px) of their micro-image centre."),
    Param("min_weight", FiniteFloat(0, 1),
          "Pixels with less than this fraction of the typical weight become NaN.", default=0.25),
    Param("depth", InputFile(), "Depth map (`plenocli depth` on the same grid and --s): each "
          "lens at its own g, the all-in-focus image (lenses of unknown depth at the map's "
          "median g; --g is not used).",
          role="input"),
    PREVIEW,
)


def check(params: dict, given: Collection[str]) -> None:
    """With a depth map every lens takes its g from the map: a --g would be ignored; the
    central band a --mask-width leaves out is a half or quarter view's."""
    if params.get("depth"):
        refuse_unused(PARAMS, given, ["g"], "is not used with --depth (each lens takes its g "
                      "from the map)")
    if params.get("view", "full") == "full":
        refuse_unused(PARAMS, given, ["mask_width"], "applies to half and quarter views only "
                      "(--view left, right, top, bottom, q00 ...)")
