import click

from plenocli.cli import options


@click.command(short_help="Decode a raw capture into a frames TIFF.")
@options.input_arg
@options.output_opt
@click.option("--camera", type=click.Choice(["auto", "canon-dp", "dng", "raytrix", "image"]),
              default="auto", show_default=True,
              help="Input kind; auto looks at the file's first bytes.")
@click.option("--frames", default=None, help="Names for the frames, comma separated (e.g. S,A).")
@click.option("--black", type=options.FiniteFloat(min=0),
              default=None, help="Black level (DN) when the file has none.")
@click.option("--white", type=options.FiniteFloat(min=0, min_open=True),
              default=None, help="White (clipping) level in DN.")
@click.option("--cfa", type=click.Choice(["RGGB", "BGGR", "GRBG", "GBRG"], case_sensitive=False),
              default=None, help="Bayer pattern at pixel (0, 0), e.g. RGGB.")
@click.option("--calib", type=options.InputFile(), default=None,
              help="Raytrix RayCalibData XML (with --camera raytrix); stored in the metadata.")
@options.preview_opt
@options.stage_command
def decode(**params):
    """Decode INPUT (Canon dual-pixel CR2, DNG, TIFF/PNG/BMP) into frames with metadata.

    Over-scan areas are kept; CFA pattern, levels and frame names go into the metadata.

    \b
    Example:
      plenocli decode IMG_0001.CR2 -o frames.tif --preview frames.png
      plenocli decode frame0.png --camera raytrix --calib calib.xml -o frames.tif
    """
    from plenocli.pipeline.stages.decode import run

    run(**params)
