import click

from plenocli.cli import options


@click.command(short_help="Calibrate the micro-lens grid from a white or scene image.")
@options.input_arg
@options.output_option(".yaml", ".yml")
@click.option("--lattice", type=click.Choice(["auto", "hex", "square"]), default="auto",
              show_default=True, help="Micro-lens lattice; auto finds the kind (a kind that "
              "does not fit the image is refused).")
@click.option("--pitch", type=options.FiniteFloat(min=4.0, max=200.0), default=None,
              help="Approximate lens pitch in px (e.g. from the datasheet): lattices within "
              "15 % are looked at too; the image decides, and an answer outside 15 % of the "
              "hint is refused.")
@click.option("--start", type=options.InputFile(), default=None,
              help="A camera calibration to refine (plenocli YAML or Raytrix XML): offset, "
              "pitch, rotation and centres are measured from the image, the report says how "
              "far each moved; a start the image contradicts is refused.")
@click.option("--xml", type=options.OutputFile(".xml"), default=None,
              help="Also write the grid as Raytrix RayCalibData XML (with lens types).")
@click.option("--compare", type=options.InputFile(), default=None,
              help="Report the distance to another grid (YAML or RayCalibData XML).")
@options.preview_opt
@options.stage_command
def calibrate(**params):
    """Estimate pitch, rotation, offset and every micro-image centre of INPUT.

    INPUT is a white image or a scene through the lens array (frames TIFF from decode, or a
    plain TIFF/PNG/BMP; views are summed, a Bayer mosaic is handled from the metadata). No hint
    is needed (hex or square, pitch 6-100 px, any rotation; --pitch takes 4-200 px). When the
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
