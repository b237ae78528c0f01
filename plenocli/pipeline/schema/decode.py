"""Parameters of ``plenocli decode``."""

from plenocli.pipeline.params import OUTPUT, PREVIEW, Param, input_arg
from plenocli.pipeline.validators import Choice, FiniteFloat, InputFile, PageNames

PARAMS = (
    input_arg(),
    OUTPUT,
    Param("camera", Choice(["auto", "canon-dp", "dng", "raytrix", "image"]),
          "Input kind; auto looks at the file's first bytes.", default="auto"),
    Param("frames", PageNames(), "Names for the frames, comma separated and distinct (e.g. S,A; "
          "not S.R, S@g3 or 1: those name other pages); one for each grey page of a plain "
          "TIFF reads them all (A,B: a dual-pixel pair saved as two images); a raw that names "
          "its frames (a CR2, most DNGs) takes none."),
    Param("black", FiniteFloat(min=0), "Black level (DN) of a plain image (raws record "
          "their own)."),
    Param("white", FiniteFloat(min=0, min_open=True), "White (clipping) level in DN of a plain "
          "image (raws record their own)."),
    Param("cfa", Choice(["RGGB", "BGGR", "GRBG", "GBRG"], case_sensitive=False),
          "Bayer pattern at pixel (0, 0) of a plain image, e.g. RGGB (raws record their own)."),
    Param("calib", InputFile(), "Raytrix RayCalibData XML (with --camera raytrix); stored in "
          "the metadata.", role="input"),
    PREVIEW,
)
