"""Parameters of ``plenocli optics``."""

from collections.abc import Collection

from plenocli.pipeline.params import Param, input_arg, refuse_unused
from plenocli.pipeline.validators import FiniteFloat, Flag, OutputFile

PARAMS = (
    input_arg(),
    Param("sensor_mm", FiniteFloat(min=0, min_open=True),
          "Side of the square sensor (mm), for the field of view.", default=3.6),
    Param("json", OutputFile(".json"), "Also write the figures as JSON here.", role="output"),
    Param("crosstalk", Flag(), "Also trace a quad-pixel micro-lens array behind the lens and "
          "report the sub-aperture cross-talk ratio, without and with a cross mask at the stop."),
    # a cross of 1/sqrt(2) of the stop or wider covers a whole quarter of the pupil
    Param("mask_width", FiniteFloat(min=0, max=0.7071, max_open=True),
          "Cross mask width as a fraction of the stop diameter (below 0.7071: a wider cross "
          "covers each quarter of the pupil).", default=1 / 15),
    Param("pixel_um", FiniteFloat(min=0.1, max=100), "Pixel size (um) for --crosstalk.",
          default=1.2),
    # beyond 1000 km the board is at infinity to a nanometre of focus, and the rays from it
    # lose their precision (1e15 mm changed r by half a point)
    Param("object_distance_mm", FiniteFloat(min=0, max=1e9, min_open=True),
          "White board distance (mm) for --crosstalk.", default=2000.0),
    Param("prism_n", FiniteFloat(min=1, max=4, min_open=True),
          "Prism index for the deviation figures.", default=1.74),
    Param("prism_apex_deg", FiniteFloat(min=0, max=90, max_open=True),
          "Prism apex angle A (deg).", default=16.7),
)


def check(params: dict, given: Collection[str]) -> None:
    """The --crosstalk options are refused without it, not ignored."""
    if not params.get("crosstalk"):
        refuse_unused(PARAMS, given, ["mask_width", "pixel_um", "object_distance_mm"],
                      "applies with --crosstalk only")
