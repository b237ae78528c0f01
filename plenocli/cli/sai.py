import click

from plenocli.cli import options


@click.command(short_help="Sub-aperture images of an N x N plenoptic sensor (Eq. 1).")
@options.input_arg
@options.output_opt
@click.option("-n", "n", type=click.IntRange(min=1), default=2, show_default=True,
              help="Pixels per micro-image side (2 for a quad-pixel sensor).")
@click.option("--grid", type=options.InputFile(), default=None,
              help="Square lens grid with a non-integer pitch: approximate SAIs (S-hat), "
                   "nearest pixel to each sub-aperture centre.")
@click.option("--cfa-layout", type=click.Choice(["pixel", "micro-image"]),
              default="pixel", show_default=True,
              help="pixel: Bayer per pixel; micro-image: one colour per micro-image (quad-Bayer).")
@options.preview_opt
@options.stage_command
def sai(**params):
    """Demultiplex FRAMES into N x N views S_ij(k, l) = L(k N + i, l N + j), named S00, S01, ...

    \b
    Example:
      plenocli sai frames.tif -n 2 -o views.tif --preview views.png
    """
    from plenocli.pipeline.stages.sai import run

    run(**params)
