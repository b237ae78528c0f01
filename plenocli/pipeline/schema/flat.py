"""Parameters of ``plenocli flat``."""

from collections.abc import Collection

from plenocli.errors import OptionError
from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, input_arg, refuse_unused
from plenocli.pipeline.validators import TIFF, Choice, FiniteFloat, InputFile, Int, OutputFile

PARAMS = (
    input_arg(),
    OUTPUT,
    Param("white", InputFile(), "Bias-corrected white image (same sensor, crop and views).",
          role="input"),
    Param("gain", InputFile(), "A gain map saved earlier with --save-gain (instead of --white).",
          role="input"),
    Param("median", Int(min=1, parity="odd"),
          "Median filter size (pixels of one colour plane, odd).", default=5),
    Param("reference", Choice(["max", "percentile"]),
          "Normalise by the maximum (paper) or a percentile.", default="max"),
    Param("percentile", FiniteFloat(0, 100), "Percentile for --reference percentile.",
          default=99.5),
    Param("floor", FiniteFloat(0, 1, max_open=True),
          "Mask (NaN) pixels whose white is below floor x reference.", default=0.05),
    Param("save_gain", OutputFile(*TIFF), "Also write the gain map, for reuse with --gain.",
          role="output"),
    PREVIEW,
)


def shared_inputs(params) -> tuple[tuple[str, str], ...]:
    """A white image flat-fielded by itself only makes sense to make its gain (--save-gain; the
    output then shows how flat the white came out): without it, one file as the frames and the
    white is a mistake."""
    return (("input", "white"),) if params.get("save_gain") else ()


def check(params: dict, given: Collection[str]) -> None:
    """One source of the gain (--white or --gain: a usage error otherwise, before any work);
    options of making a gain do nothing to a saved one (--gain: read, not made), and
    --percentile is only the percentile reference's."""
    if (params.get("white") is None) == (params.get("gain") is None):
        raise OptionError("give exactly one of --white (a bias-corrected white image) or "
                          "--gain (a gain map saved with --save-gain)")
    if params.get("gain"):
        refuse_unused(PARAMS, given, ["median", "reference", "percentile", "floor"],
                      "makes a gain from --white; a saved --gain keeps the options it was "
                      "made with")
    elif params.get("reference", "max") == "max":
        refuse_unused(PARAMS, given, ["percentile"], "applies to --reference percentile only")
