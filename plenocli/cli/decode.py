import click

from plenocli.cli import options
from plenocli.pipeline.schema import decode as schema


@click.command(short_help="Decode a raw capture into a frames TIFF.")
@options.declared(schema.PARAMS)
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
