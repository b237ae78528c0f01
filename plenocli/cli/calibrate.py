import click

from plenocli.cli import options
from plenocli.pipeline.schema import calibrate as schema


@click.command(short_help="Calibrate the micro-lens grid from a white or scene image.")
@options.declared(schema.PARAMS)
@options.stage_command
def calibrate(**params):
    """Estimate pitch, rotation, offset and every micro-image centre of INPUT.

    INPUT is a white image or a scene through the lens array (frames TIFF from decode, or a
    plain TIFF/PNG/BMP; views are summed, a Bayer mosaic is handled from the metadata). No hint
    is needed (hex or square, pitch 6-100 px, any rotation; --pitch takes 3-200 px). When the
    lattice is not certain (a rival lattice fits almost as well) the command stops and names
    the rivals: pass --pitch, a white image, or --start. The YAML holds the lattice, every
    lens (i, j, x, y), the lens types of a multi-focus array, the residuals and the confidence.

    \b
    Example:
      plenocli calibrate white.tif -o grid.yaml --xml grid.xml --preview grid.png
      plenocli calibrate frame0.png -o grid.yaml --start calib.xml
    """
    from plenocli.pipeline.stages.calibrate import run

    run(**params)
