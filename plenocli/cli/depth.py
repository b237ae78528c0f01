import click

from plenocli.cli import options
from plenocli.pipeline.schema import depth as schema


@click.command(short_help="Depth from one snapshot (lenslet g, dual/quad-pixel disparity).")
@options.declared(schema.PARAMS)
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
