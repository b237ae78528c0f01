import click

from plenocli.cli import options
from plenocli.pipeline.validators import InputFile


@click.command(short_help="Show what a raw, plenocli TIFF, lens grid or XML file holds.")
@click.argument("file", type=options.Declared(InputFile()))
@click.option("--json", "as_json", is_flag=True, help="Print JSON (for scripts).")
@options.stage_command
def info(file, as_json):
    """Describe FILE: camera, frames, sizes, CFA, black/white levels, over-scan areas and the
    provenance (stage, parameters, inputs, history) of a plenocli output.

    \b
    Example:
      plenocli info fixtures/dualpixel/capture.dng
      plenocli info out/demo/dualpixel/views.tif --json
    """
    import json

    from plenocli.io.info import describe, format_info
    from plenocli.pipeline.records import read_record

    described = describe(file, record=read_record(file))
    click.echo(json.dumps(described, indent=2, default=str) if as_json else format_info(described))
