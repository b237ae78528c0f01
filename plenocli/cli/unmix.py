import click

from plenocli.cli import options


@click.command(short_help="Remove sub-aperture cross-talk (ghosts) with a measured mixing.")
@click.argument("inputs", nargs=-1, required=True, type=options.InputFile())
@options.output_opt
@click.option("--mixing", required=True, type=options.InputFile(),
              help="Mixing file from plenocli crosstalk --mixing-out (masked whites of this rig, "
                   "processed like these views).")
@click.option("--regularise", type=options.FiniteFloat(min=0.0, max=1.0), default=0.0,
              show_default=True,
              help="Tikhonov lambda (units of M, diagonal 1): damps ill-conditioned pixels; "
                   "0 = exact inverse.")
@click.option("--noise-map", type=options.OutputFile(*options.TIFF), default=None,
              help="Also write the per-pixel noise gain of every unmixed view (TIFF).")
@options.preview_opt
@options.stage_command
def unmix(**params):
    """Solve, per pixel, the mixing O_k = sum_j M_kj T_j of the views for the clean views T.

    INPUTS is a views TIFF (or one TIFF per view, e.g. left.tif right.tif); the pages the
    mixing names are replaced by their clean versions, every other page is kept, so stitch
    takes the output as it is. The metadata records the noise gain (median, max) and the
    mixing's condition numbers; NaN stays NaN.

    \b
    Example:
      plenocli unmix views.tif --mixing mixing.tif -o clean.tif --noise-map gain.tif
    """
    from plenocli.pipeline.stages.unmix import run

    run(**params)
