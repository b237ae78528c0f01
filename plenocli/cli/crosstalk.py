import click

from plenocli.cli import options


@click.command(short_help="Measure sub-aperture cross-talk from masked white captures.")
@click.argument("inputs", nargs=-1, required=True, type=options.InputFile())
@options.output_option(".json")
@click.option("--views", default=None,
              help="Views to compare, by name or page number, e.g. A,B (leaves out the sum view "
                   "S that bias writes); default: all pages.")
@click.option("--intended", default=None,
              help="Name of the view whose pupil part was open (one, or one per input, comma "
                   "separated); default: the brightest view. With --mask-widths: left|right.")
@click.option("--tile", type=click.IntRange(min=2), default=64, show_default=True,
              help="Tile side (px, even) of the cross-talk map.")
@options.preview_opt
@click.option("--mask-widths", default=None,
              help="Raytrix sweep: mask widths m (px), e.g. 0,1,2,3; INPUT is then a frames TIFF "
                   "and --grid is needed (uses plenocli refocus).")
@click.option("--grid", type=options.InputFile(), default=None,
              help="Lens grid YAML (only with --mask-widths).")
@click.option("--s", "s", type=options.FiniteFloat(min=0, min_open=True),
              default=0.2, show_default=True,
              help="Refocus scale s (only with --mask-widths).")
@click.option("--g", "g", type=options.FiniteFloat(min=0, min_open=True),
              default=4.0, show_default=True,
              help="Refocus g (only with --mask-widths).")
@click.option("--mixing-out", type=options.OutputFile(*options.TIFF), default=None,
              help="Also write the mixing-matrix field M (TIFF) for plenocli unmix; needs one "
                   "masked white per pupil part (with --intended naming each one's open part).")
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
