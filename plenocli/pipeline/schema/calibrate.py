"""Parameters of ``plenocli calibrate``."""

from plenocli.pipeline.params import PREVIEW, Param, input_arg, output_param
from plenocli.pipeline.validators import Choice, FiniteFloat, InputFile, OutputFile

PARAMS = (
    input_arg(),
    output_param(".yaml", ".yml"),
    Param("lattice", Choice(["auto", "hex", "square"]), "Micro-lens lattice; auto finds the "
          "kind (a kind that does not fit the image is refused).", default="auto"),
    Param("pitch", FiniteFloat(min=3.0, max=200.0), "Approximate lens pitch in px (e.g. from "
          "the datasheet): lattices within 15 % are looked at too; the image decides, and an "
          "answer outside 15 % of the hint is refused."),
    Param("start", InputFile(), "A camera calibration to refine (plenocli YAML or Raytrix XML): "
          "offset, pitch, rotation and centres are measured from the image, the report says "
          "how far each moved; a start the image contradicts is refused.", role="input"),
    Param("xml", OutputFile(".xml"), "Also write the grid as Raytrix RayCalibData XML (with "
          "lens types).", role="output"),
    Param("compare", InputFile(), "Report the distance to another grid (YAML or RayCalibData "
          "XML).", role="input"),
    PREVIEW,
)


def shared_inputs(params) -> tuple[tuple[str, str], ...]:
    """The grid a calibration starts from may be the one it is compared with (how far the
    calibration moved it)."""
    return (("start", "compare"),)
