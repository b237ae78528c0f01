import click

from plenocli.cli import options


class GValues(click.ParamType):
    """One g, a list 2,3,4 or a range 2:6:0.5, checked by the library's own parser."""

    name = "G"

    def convert(self, value, param, ctx):
        from plenocli.refocus import parse_g

        try:
            parse_g(str(value))
        except ValueError as err:
            self.fail(str(err), param, ctx)
        return str(value).strip()


@click.command(short_help="Refocus a focused-plenoptic capture (Lanczos splatting, Eq. 3).")
@options.input_arg
@options.output_opt
@click.option("--grid", required=True, type=options.InputFile(),
              help="Lens grid (plenocli YAML from `plenocli calibrate`).")
@click.option("--s", "s", type=options.FiniteFloat(min=0, min_open=True),
              default=0.2, show_default=True,
              help="Size of the refocused image relative to the sensor image.")
@click.option("--g", "g", type=GValues(), default="4", show_default=True,
              help="Refocus parameter; a list (2,3,4) or range (2:6:0.5, stop included) "
                   "makes a focal sweep: one page per g and a sharpness score per g.")
@click.option("--view", type=click.Choice(["full", "left", "right", "top", "bottom", "q00",
                                          "q01", "q10", "q11"]), default="full", show_default=True,
              help="Pupil mask: the whole micro-image, a half or a quadrant.")
@click.option("--mask-width", type=options.FiniteFloat(min=0), default=2.0, show_default=True,
              help="Width m (px) of the central band left out of half views.")
@click.option("--kernel", type=click.Choice(["lanczos2", "lanczos3", "lanczos4", "bilinear"]),
              default="lanczos3", show_default=True,
              help="Splatting kernel.")
@click.option("--radius", type=options.FiniteFloat(min=0, min_open=True), default=None,
              help="Use only pixels within this distance (px) of their micro-image centre.")
@click.option("--min-weight", type=options.FiniteFloat(0, 1), default=0.25, show_default=True,
              help="Pixels with less than this fraction of the typical weight become NaN.")
@click.option("--depth", type=options.InputFile(), default=None,
              help="Depth map (`plenocli depth` on the same grid and --s): each lens at its "
                   "own g, the all-in-focus image; --g only where the depth is unknown.")
@options.preview_opt
@options.stage_command
def refocus(**params):
    """Refocus FRAMES with a lens grid: (X, Y) = s (g ((x, y) - c_ij) + c_ij).

    Every sensor pixel is splatted with a Lanczos kernel at (X, Y) into a sum and a weight map;
    the result is sum / weight, NaN where too few samples landed. Bayer frames give R, G, B
    pages (each colour splatted on its own, no demosaicing). With several g values the output
    holds one page per g (names like G@g3.5) and the sharpness of each is logged and stored.

    \b
    Example:
      plenocli refocus frames.tif --grid grid.yaml --s 0.2 --g 4 --view left -o left.tif
      plenocli refocus frames.tif --grid grid.yaml --g 2:6:0.5 -o sweep.tif --preview best.png
    """
    from plenocli.pipeline.stages.refocus import run

    run(**params)
