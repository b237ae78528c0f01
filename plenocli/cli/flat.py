import click

from plenocli.cli import options


@click.command(short_help="Correct vignetting with a gain from a white image.")
@options.input_arg
@options.output_opt
@click.option("--white", type=options.InputFile(), default=None,
              help="Bias-corrected white image (same sensor, crop and views).")
@click.option("--gain", type=options.InputFile(), default=None,
              help="A gain map saved earlier with --save-gain (instead of --white).")
@click.option("--median", type=click.IntRange(min=1), default=5, show_default=True,
              help="Median filter size (pixels of one colour plane, odd).")
@click.option("--reference", type=click.Choice(["max", "percentile"]), default="max",
              show_default=True, help="Normalise by the maximum (paper) or a percentile.")
@click.option("--percentile", type=options.FiniteFloat(0, 100), default=99.5, show_default=True,
              help="Percentile for --reference percentile.")
@click.option("--floor", type=options.FiniteFloat(0, 1, max_open=True), default=0.05,
              show_default=True, help="Mask (NaN) pixels whose white is below floor x reference.")
@click.option("--save-gain", type=options.OutputFile(*options.TIFF), default=None,
              help="Also write the gain map, for reuse with --gain.")
@options.preview_opt
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
