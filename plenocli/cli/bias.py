import click

from plenocli.cli import options


@click.command(short_help="Subtract the bias measured in the over-scan areas.")
@options.input_arg
@options.output_opt
@click.option("--overscan", type=click.Choice(["auto", "left", "top", "both", "none"]),
              default="auto", show_default=True,
              help="Over-scan to use: left (per row), top (per column), both, or none (the "
                   "file's black level). auto: left, else top, else none.")
@click.option("--smooth", type=click.IntRange(min=0), default=0, show_default=True,
              help="Running mean of the per-row levels over this many rows of one colour.")
@click.option("--guard", type=click.IntRange(min=0), default=2, show_default=True,
              help="Pixels ignored at each edge of an over-scan area.")
@click.option("--crop", type=options.RowsCols(),
              default=None, help="Central crop ROWSxCOLS of the active area, e.g. "
              "2000x2000 (CFA phase kept).")
@options.preview_opt
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
