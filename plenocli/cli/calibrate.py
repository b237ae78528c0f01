import click

from plenocli.cli import options


@click.command(short_help="Calibrate the micro-lens grid from a white image.")
@options.input_arg
@options.output_opt
@click.option("--lattice", type=click.Choice(["hex", "square"]), default="hex",
              show_default=True, help="Micro-lens lattice.")
@click.option("--xml", type=click.Path(dir_okay=False), default=None,
              help="Also write the grid as Raytrix RayCalibData XML.")
@click.option("--compare", type=click.Path(dir_okay=False), default=None,
              help="Report the distance to another grid (YAML or RayCalibData XML).")
@options.preview_opt
@options.stage_command
def calibrate(**params):
    """Estimate pitch, rotation, offset and every micro-image centre of INPUT.

    INPUT is a white image (frames TIFF from decode, or a plain TIFF/PNG/BMP; views are summed,
    a Bayer mosaic is handled from the metadata). No pitch or rotation hint is needed (pitch
    6-60 px, any rotation). A scene image works too (lattice only). The YAML holds the lattice,
    every lens (i, j, x, y) and the residual report.

    \b
    Example:
      plenocli calibrate white.tif -o grid.yaml --xml grid.xml --preview grid.png
      plenocli calibrate frame0.png -o grid.yaml --compare calib.xml
    """
    from plenocli.pipeline.stages.calibrate import run

    run(**params)
