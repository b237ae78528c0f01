"""``plenocli``: the command group. One module per command in this package."""

import click

from plenocli import __version__
from plenocli.cli.decode import decode
from plenocli.cli.optics import optics


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="plenocli")
def cli():
    """Raw-processing pipeline for plenoptic captures.

    Each command is one stage; `plenocli run CONFIG.yaml` chains them.
    """


for command in (decode, optics):
    cli.add_command(command)
