"""Parameters of ``plenocli unmix``."""

from plenocli.model.mixing import MAX_REGULARISE
from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, inputs_arg
from plenocli.pipeline.validators import TIFF, FiniteFloat, InputFile, OutputFile

PARAMS = (
    inputs_arg(),
    OUTPUT,
    Param("mixing", InputFile(), "Mixing file from plenocli crosstalk --mixing-out (masked "
          "whites of this rig, processed like these views).", role="input", required=True),
    Param("regularise", FiniteFloat(min=0.0, max=MAX_REGULARISE), "Tikhonov lambda (units of M, "
          "diagonal 1): damps ill-conditioned pixels; 0 = exact inverse.", default=0.0),
    Param("noise_map", OutputFile(*TIFF),
          "Also write the per-pixel noise gain of every unmixed view (TIFF).", role="output"),
    PREVIEW,
)
