import click

from plenocli.cli import options


class GRange(click.ParamType):
    """MIN:MAX of the g search, checked by the stage's own parser."""

    name = "MIN:MAX"

    def convert(self, value, param, ctx):
        from plenocli.pipeline.stages.depth import parse_range

        try:
            parse_range(str(value))
        except ValueError as err:
            self.fail(str(err), param, ctx)
        return str(value).strip()


@click.command(short_help="Depth from one snapshot (lenslet g, dual/quad-pixel disparity).")
@options.input_arg
@options.output_opt
@click.option("--grid", type=options.InputFile(), default=None,
              help="Lens grid (YAML or RayCalibData XML): INPUT is lenslet frames. Without "
                   "it INPUT holds dual-pixel views A, B or quad-pixel SAIs S00..S11.")
@click.option("--s", "s", type=options.FiniteFloat(min=0, min_open=True), default=0.2,
              show_default=True, help="Output grid of `plenocli refocus --s S` (lenslet).")
@click.option("--g", "g", type=GRange(), default="2:8", show_default=True,
              help="Search range of g (lenslet); Galilean cameras: negative, e.g. -8:-2.")
@click.option("--min-confidence", type=options.FiniteFloat(0, 1), default=0.1,
              show_default=True, help="Lenses below this confidence leave g unknown (NaN).")
@click.option("--max-disparity", type=options.FiniteFloat(0.5, 64), default=4.0,
              show_default=True, help="Largest |disparity| searched (px, dual/quad-pixel).")
@click.option("--camera", type=options.InputFile(), default=None,
              help="Camera YAML (focal_length_mm, focus_distance_m, mla_sensor_mm): adds a "
                   "depth_m page (lenslet).")
@options.preview_opt
@options.stage_command
def depth(**params):
    """Depth map of lenslet FRAMES (page g: the refocus g at which each point is in focus) or
    of dual/quad-pixel VIEWS (page disparity: B's shift against A, px), with a confidence page.

    \b
    Examples:
      plenocli depth frames.tif --grid grid.yaml --g 2:8 -o depth.tif --preview depth.png
      plenocli depth views.tif -o disparity.tif
    """
    from plenocli.pipeline.stages.depth import run

    run(**params)
