"""Parameters of ``plenocli unmix``."""

from collections.abc import Collection

from plenocli.errors import OptionError
from plenocli.model.mixing import MAX_REGULARISE
from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, inputs_arg
from plenocli.pipeline.validators import TIFF, FiniteFloat, InputFile, NameList, OutputFile

PARAMS = (
    inputs_arg(),
    OUTPUT,
    Param("mixing", InputFile(), "Mixing file from plenocli crosstalk --mixing-out (masked "
          "whites of this rig, processed like these views).", role="input", required=True),
    Param("views", NameList(), "With one TIFF per view: the views' names, in the inputs' "
          "order (e.g. left,right, as the mixing names them); default: each file's name."),
    Param("regularise", FiniteFloat(min=0.0, max=MAX_REGULARISE), "Tikhonov lambda (units of M, "
          "diagonal 1): damps ill-conditioned pixels; 0 = exact inverse.", default=0.0),
    Param("noise_map", OutputFile(*TIFF),
          "Also write the per-pixel noise gain of every unmixed view (TIFF).", role="output"),
    PREVIEW,
)


def check(params: dict, given: Collection[str]) -> None:
    """--views names files of one view each, one name per file."""
    if params.get("views") is None:
        return
    named, inputs = params["views"].split(","), list(params.get("inputs") or ())
    if len(named) != len(inputs) or len(inputs) < 2:
        raise OptionError(f"--views names {len(named)} view(s) for {len(inputs)} input(s): it "
                          "names the views of one TIFF per view, one name per file in order "
                          "(a views TIFF names its own pages)")
    if "" in named or len(set(named)) != len(named):
        raise OptionError(f"--views {params['views']}: give each view one name")
