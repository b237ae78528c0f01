import click

from plenocli.cli import options
from plenocli.pipeline.schema import crosstalk as schema


@click.command(short_help="Measure sub-aperture cross-talk from masked white captures.")
@options.declared(schema.PARAMS)
@options.stage_command
def crosstalk(**params):
    """Cross-talk ratio r = max flux on another view / flux on the intended view.

    Each INPUT is a views TIFF of a white target shot with all but one part of the pupil masked.
    r is reported globally, as a map over tiles and per colour (Bayer views), in a JSON report;
    --preview draws the maps as a heat map. NaN pixels are ignored. With --mixing-out the
    inputs are one masked white per pupil part, and the whole mixing matrix M (view k records
    sum_j M_kj T_j) is measured per tile and colour and written for plenocli unmix.

    \b
    Example:
      plenocli crosstalk white_maskR.tif white_maskL.tif --views A,B --intended A,B \\
          -o crosstalk.json --preview crosstalk.png
      plenocli crosstalk masked_A.tif masked_B.tif --views A,B --intended A,B \\
          -o crosstalk.json --mixing-out mixing.tif
    """
    from plenocli.pipeline.stages.crosstalk import run

    run(**params)
