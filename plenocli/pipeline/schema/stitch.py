"""Parameters of ``plenocli stitch``."""

from collections.abc import Collection

from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, inputs_arg, refuse_unused
from plenocli.pipeline.validators import (
    Choice,
    FiniteFloat,
    InputFile,
    OutputFile,
    ViewList,
)

_FRACTION = FiniteFloat(min=0, max=1, min_open=True, max_open=True)

PARAMS = (
    inputs_arg(),
    OUTPUT,
    Param("views", ViewList(), "Views to stitch, by name or page number, comma separated "
          "(e.g. A,B)."),
    Param("layout", Choice(["auto", "1x2", "2x1", "2x2"]),
          "Arrangement, views row-major (2x2: S00,S01,S10,S11).", default="auto"),
    Param("model", Choice(["auto", "translation", "homography"]), "Geometric model between "
          "views (auto: a --transform-in's own, else translation).", default="auto"),
    Param("distortion", FiniteFloat(min=-1, max=1, min_open=True), "Known radial distortion K1 "
          "removed first (r_d = r_u (1 + K1 r_u^2), r in half-diagonals).", default=0.0),
    Param("rig", InputFile(), "Prism rig YAML (focal_mm, sensor_mm, prism_n, prism_apex_deg, "
          "views): cancel the prisms' distortion and search near the predicted overlap "
          "(configs/rigs/).", role="input"),
    Param("overlap", _FRACTION,
          "Expected overlap, fraction of the view (e.g. 0.2); restricts the search."),
    Param("overlap_tolerance", _FRACTION, "Tolerance on --overlap (fraction of the view).",
          default=0.1),
    Param("transform_in", InputFile(),
          "Reapply a transform saved with --transform-out instead of registering.", role="input"),
    Param("transform_out", OutputFile(".json"),
          "Save the transform (JSON) to reapply to later captures of the same rig.",
          role="output"),
    Param("blend", Choice(["feather", "multiband"]), "Seam blending.", default="feather"),
    Param("gains", Choice(["match", "none"]), "Exposure: match each view's gains to view 0 from "
          "the overlaps (views above black), or keep the views as recorded.", default="match"),
    Param("report", OutputFile(".json"),
          "Write a JSON report (model, parameters, overlap, inliers, residual px).",
          role="output"),
    PREVIEW,
)


def check(params: dict, given: Collection[str]) -> None:
    """The overlap options only narrow a search: a saved transform is applied, not searched
    for, and a rig predicts the overlap itself."""
    if params.get("transform_in"):
        refuse_unused(PARAMS, given, ["overlap", "overlap_tolerance"],
                      "narrows the search; --transform-in applies a saved transform")
    elif params.get("rig"):
        refuse_unused(PARAMS, given, ["overlap", "overlap_tolerance"],
                      "narrows the search without a rig; --rig predicts the overlap")
    elif params.get("overlap") is None:
        refuse_unused(PARAMS, given, ["overlap_tolerance"], "applies with --overlap only")
