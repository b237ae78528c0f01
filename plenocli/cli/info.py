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
    if described["kind"] == "pipeline-config":
        described["refused"] = _config_refused(file)
    click.echo(json.dumps(described, indent=2, default=str) if as_json else format_info(described))


def _config_refused(path: str) -> str | None:
    """Why ``plenocli run`` (or batch) would refuse the config before any step, or None."""
    from plenocli.errors import PlenocliError
    from plenocli.pipeline.config import read_template

    try:
        template = read_template(path)
        if not template.per_capture_steps() and (template.out or not template.uses_out()):
            template.steps()   # every step's stage, keys and values, as run checks them
    except PlenocliError as err:
        return " ".join(str(err).split())
    return None
