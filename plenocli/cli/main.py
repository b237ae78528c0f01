"""``plenocli``: the command group. One module per command in this package."""

import click

from plenocli import __version__
from plenocli.cli.batch import batch
from plenocli.cli.bias import bias
from plenocli.cli.calibrate import calibrate
from plenocli.cli.crosstalk import crosstalk
from plenocli.cli.decode import decode
from plenocli.cli.flat import flat
from plenocli.cli.info import info
from plenocli.cli.optics import optics
from plenocli.cli.refocus import refocus
from plenocli.cli.run import run
from plenocli.cli.sai import sai
from plenocli.cli.simulate import simulate
from plenocli.cli.stitch import stitch
from plenocli.cli.unmix import unmix


class PipelineOrder(click.Group):
    """Lists the commands in the order they were added (pipeline order), not alphabetically."""

    def list_commands(self, ctx):
        return list(self.commands)


@click.group(cls=PipelineOrder,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="plenocli")
def cli():
    """Raw-processing pipeline for plenoptic captures.

    Each command is one stage; `plenocli run CONFIG.yaml` chains them.
    """


# in pipeline order
for command in (
    decode,
    bias,
    flat,
    calibrate,
    refocus,
    sai,
    crosstalk,
    unmix,
    stitch,
    run,
    batch,
    info,
    simulate,
    optics,
):
    cli.add_command(command)
