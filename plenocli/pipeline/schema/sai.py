"""Parameters of ``plenocli sai``."""

from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, input_arg
from plenocli.pipeline.validators import Choice, InputFile, Int

PARAMS = (
    input_arg(),
    OUTPUT,
    Param("n", Int(min=1), "Pixels per micro-image side (2 for a quad-pixel sensor).",
          default=2, flags=("-n",)),
    Param("grid", InputFile(), "Square lens grid with a non-integer pitch: approximate SAIs "
          "(S-hat), nearest pixel to each sub-aperture centre.", role="input"),
    Param("cfa_layout", Choice(["pixel", "micro-image"]), "pixel: Bayer per pixel; micro-image: "
          "one colour per micro-image (quad-Bayer).", default="pixel"),
    PREVIEW,
)
