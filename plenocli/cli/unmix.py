import click

from plenocli.cli import options
from plenocli.pipeline.schema import unmix as schema


@click.command(short_help="Remove sub-aperture cross-talk (ghosts) with a measured mixing.")
@options.declared(schema.PARAMS)
@options.stage_command
def unmix(**params):
    """Solve, per pixel, the mixing O_k = sum_j M_kj T_j of the views for the clean views T.

    INPUTS is a views TIFF (or one TIFF per view, e.g. left.tif right.tif); the pages the
    mixing names are replaced by their clean versions, every other page is kept, so stitch
    takes the output as it is; a dual-pixel sum S is made again as A + B of the clean views
    (left out after flat, where it is not their sum). The metadata records the noise gain
    (median, max) and the mixing's condition numbers; NaN stays NaN.

    \b
    Example:
      plenocli unmix views.tif --mixing mixing.tif -o clean.tif --noise-map gain.tif
    """
    from plenocli.pipeline.stages.unmix import run

    run(**params)
