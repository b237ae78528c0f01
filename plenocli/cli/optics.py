import click

from plenocli.cli import options


@click.command(short_help="Figures of a lens prescription (focal length, field, distortion).")
@options.input_arg
@click.option("--sensor-mm",
              type=options.FiniteFloat(min=0, min_open=True), default=3.6, show_default=True,
              help="Side of the square sensor (mm), for the field of view.")
@click.option("--json", type=options.OutputFile(".json"), default=None,
              help="Also write the figures as JSON here.")
@click.option("--crosstalk", is_flag=True,
              help="Also trace a quad-pixel micro-lens array behind the lens and report the "
                   "sub-aperture cross-talk ratio, without and with a cross mask at the stop.")
@click.option("--mask-width",
              type=options.FiniteFloat(min=0, max=1, max_open=True),
              default=1 / 15, show_default=True,
              help="Cross mask width as a fraction of the stop diameter.")
@click.option("--pixel-um",
              type=options.FiniteFloat(min=0.1, max=100), default=1.2, show_default=True,
              help="Pixel size (um) for --crosstalk.")
@click.option("--object-distance-mm",
              type=options.FiniteFloat(min=0, min_open=True), default=2000.0, show_default=True,
              help="White board distance (mm) for --crosstalk.")
@click.option("--prism-n", type=options.FiniteFloat(min=1, max=4, min_open=True), default=1.74,
              show_default=True,
              help="Prism index for the deviation figures.")
@click.option("--prism-apex-deg",
              type=options.FiniteFloat(min=0, max=90, max_open=True),
              default=16.7, show_default=True,
              help="Prism apex angle A (deg).")
@options.stage_command
def optics(**params):
    """Print the figures of the lens prescription INPUT (YAML).

    Effective focal length, back focal distance, pupils, field of view for the sensor,
    distortion and RMS spot size over the field, prism deviation; with --crosstalk the
    quad-pixel sub-aperture cross-talk ratio.

    \b
    Example:
      plenocli optics configs/lenses/paper_table2.yaml --sensor-mm 3.6 --json table2.json
    """
    from plenocli.pipeline.stages.optics import format_report, run

    click.echo(format_report(run(**params)))
