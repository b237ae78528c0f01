import click

from plenocli.cli import options
from plenocli.pipeline.schema import sai as schema


@click.command(short_help="Sub-aperture images of an N x N plenoptic sensor (Eq. 1).")
@options.declared(schema.PARAMS)
@options.stage_command
def sai(**params):
    """Demultiplex FRAMES into N x N views S_ij(k, l) = L(k N + i, l N + j), named S00, S01, ...

    \b
    Example:
      plenocli sai frames.tif -n 2 -o views.tif --preview views.png
    """
    from plenocli.pipeline.stages.sai import run

    run(**params)
