"""Parameters of ``plenocli bias``."""

from collections.abc import Collection

from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, input_arg, refuse_unused
from plenocli.pipeline.validators import Choice, Int, RowsCols

PARAMS = (
    input_arg(),
    OUTPUT,
    Param("overscan", Choice(["auto", "left", "top", "both", "none"]),
          "Over-scan to use: left (per row), top (per column), both, or none (the file's black "
          "level). auto: left, else top, else none.", default="auto"),
    Param("smooth", Int(min=0), "Running mean of the per-row levels over this many rows of one "
          "colour.", default=0),
    Param("guard", Int(min=0), "Pixels ignored at each edge of an over-scan area.", default=2),
    Param("crop", RowsCols(), "Central crop ROWSxCOLS of the active area, e.g. 2000x2000 (CFA "
          "phase kept)."),
    PREVIEW,
)


def check(params: dict, given: Collection[str]) -> None:
    """The over-scan options do nothing when no over-scan is read."""
    if params.get("overscan") == "none":
        refuse_unused(PARAMS, given, ["smooth", "guard"],
                      "applies to the over-scan levels; --overscan none takes the file's black "
                      "level")
