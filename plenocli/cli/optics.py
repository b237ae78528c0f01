import click

from plenocli.cli import options
from plenocli.pipeline.schema import optics as schema


@click.command(short_help="Figures of a lens prescription (focal length, field, distortion).")
@options.declared(schema.PARAMS)
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
    from plenocli.progress import when_landed

    report = format_report(run(**params))
    when_landed(lambda: click.echo(report))  # once --json has landed
