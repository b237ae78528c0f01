import click

from plenocli.cli import options
from plenocli.pipeline.schema import flat as schema


@click.command(short_help="Correct vignetting with a gain from a white image.")
@options.declared(schema.PARAMS)
@options.stage_command
def flat(**params):
    """Vignetting correction: median-filter the white image, normalise, invert to a gain.

    Per CFA colour and per view (A and B have their own fall-off).

    \b
    Example:
      plenocli flat biased.tif --white white_biased.tif --save-gain gain.tif -o flat.tif
    """
    from plenocli.pipeline.stages.flat import run

    run(**params)
