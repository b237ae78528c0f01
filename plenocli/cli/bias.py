import click

from plenocli.cli import options
from plenocli.pipeline.schema import bias as schema


@click.command(short_help="Subtract the bias measured in the over-scan areas.")
@options.declared(schema.PARAMS)
@options.stage_command
def bias(**params):
    """Bias-correct decoded FRAMES per row and CFA colour, crop to the active area.

    Dual-pixel captures (frames S and A) give views A, B = S - A and S; pixels where a raw value
    is clipped are NaN in every view derived from it.

    \b
    Example:
      plenocli bias frames.tif --smooth 9 -o biased.tif
    """
    from plenocli.pipeline.stages.bias import run

    run(**params)
