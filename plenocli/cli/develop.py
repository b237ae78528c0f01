import click

from plenocli.cli import options
from plenocli.colour.demosaic import DEFAULT_METHOD, METHODS
from plenocli.model.colour import OUTPUT_SPACES

MAX_GAIN_RATIO = 100.0  # beyond any light source: a typo, and float overflow further on


class WhiteBalance(click.ParamType):
    """``as-shot`` or three positive finite gains ``R,G,B``."""

    name = "as-shot|R,G,B"

    def convert(self, value, param, ctx):
        text = str(value).strip()
        if text == "as-shot":
            return text
        parts = text.split(",")
        try:
            gains = [float(p) for p in parts]
        except ValueError:
            gains = []
        if len(gains) != 3 or not all(g > 0 and g < float("inf") for g in gains):
            self.fail(f"{value!r}: give as-shot or three positive gains R,G,B (e.g. 2.1,1,1.6)",
                      param, ctx)
        if max(gains) > MAX_GAIN_RATIO * min(gains):
            self.fail(f"{value!r}: one gain is more than {MAX_GAIN_RATIO:g} times another; "
                      "white-balance gains are within a few times each other (e.g. 2.1,1,1.6)",
                      param, ctx)
        return ",".join(repr(g) for g in gains)


@click.command(short_help="Develop a colour view into a photograph (TIFF, JPEG, PNG).")
@options.input_arg
@options.output_option()
@click.option("--view", default=None,
              help="Which view to develop (e.g. S); needed when the file holds several.")
@click.option("--method", type=click.Choice(METHODS), default=DEFAULT_METHOD,
              show_default=True, help="Demosaicing method (docs/colour.md compares them).")
@click.option("--wb", type=WhiteBalance(), default="as-shot", show_default=True,
              help="White balance: the raw's as-shot gains, or R,G,B multipliers.")
@click.option("--wb-from", type=options.InputFile(), default=None,
              help="White balance measured on a white image (bias-corrected views TIFF).")
@click.option("--matrix", type=click.Choice(["as-shot", "none"]), default="as-shot",
              show_default=True,
              help="Camera colour matrix from the raw, or none (camera RGB taken as sRGB).")
@click.option("--space", type=click.Choice(list(OUTPUT_SPACES)), default="srgb",
              show_default=True, help="Output colour space (its ICC profile is embedded).")
@click.option("--exposure", type=options.FiniteFloat(min=-10, max=10), default=0.0,
              show_default=True,
              help="Exposure (EV) on top of the automatic white point (99th percentile = 1).")
@click.option("--quality", type=click.IntRange(1, 100), default=95, show_default=True,
              help="JPEG quality.")
@click.option("--recover-highlights", type=options.InputFile(), default=None,
              help="Dual-pixel: rebuild S (and B) from A where only S clipped, with the A/S "
                   "split of this white image (views A, B, S, processed like INPUT).")
@click.option("--linear", type=options.OutputFile(*options.TIFF), default=None,
              help="Also write the scene-referred linear sRGB as a float32 TIFF (R, G, B pages).")
@options.preview_opt
@options.stage_command
def develop(**params):
    """Demosaic one view of INPUT, white-balance it, apply the camera's colour matrix and write
    an output-referred image (.tif 16-bit, .jpg or .png 8-bit) with ICC profile and EXIF.

    \b
    Example:
      plenocli develop views.tif --view S -o S.jpg --preview S.png
      plenocli develop views.tif --view A --wb-from white.tif --space display-p3 -o A.tif
    """
    from plenocli.pipeline.stages.develop import run

    run(**params)
