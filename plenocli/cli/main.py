"""``plenocli``: the command group. One module per command in this package.

Commands are loaded lazily: ``plenocli --help`` lists them from the table below without
importing any of them (the simulator alone pulls in scipy.ndimage, OpenCV and tifffile), and
``plenocli STAGE`` imports only ``plenocli.cli.STAGE``. tests/cli/test_main.py checks that the
short help strings here match the commands' own.
"""

from __future__ import annotations

import importlib

import click

from plenocli import __version__

# name -> short help, in pipeline order (the order of the listing); the command object is the
# function of the same name in plenocli.cli.<name>
COMMANDS: dict[str, str] = {
    "decode": "Decode a raw capture into a frames TIFF.",
    "bias": "Subtract the bias measured in the over-scan areas.",
    "flat": "Correct vignetting with a gain from a white image.",
    "calibrate": "Calibrate the micro-lens grid from a white or scene image.",
    "refocus": "Refocus a focused-plenoptic capture (Lanczos splatting, Eq. 3).",
    "depth": "Depth from one snapshot (lenslet g, dual/quad-pixel disparity).",
    "sai": "Sub-aperture images of an N x N plenoptic sensor (Eq. 1).",
    "crosstalk": "Measure sub-aperture cross-talk from masked white captures.",
    "unmix": "Remove sub-aperture cross-talk (ghosts) with a measured mixing.",
    "stitch": "Stitch 2 or 4 views into an extended-FOV panorama.",
    "develop": "Develop a colour view into a photograph (TIFF, JPEG, PNG).",
    "run": "Run a pipeline config (make-style).",
    "batch": "Run a pipeline template over many captures, in parallel.",
    "info": "Show what a raw, plenocli TIFF, lens grid or XML file holds.",
    "simulate": "Write synthetic captures with ground truth.",
    "optics": "Figures of a lens prescription (focal length, field, distortion).",
}


class LazyGroup(click.Group):
    """A group whose commands are imported when called (or their own help is shown), listed
    in pipeline order with the short help of ``COMMANDS``."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        if cmd_name not in self.commands:
            module = importlib.import_module(f"plenocli.cli.{cmd_name}")
            self.add_command(getattr(module, cmd_name), cmd_name)
        return self.commands[cmd_name]

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = [(name, COMMANDS[name]) for name in self.list_commands(ctx)]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=LazyGroup,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="plenocli")
def cli():
    """Raw-processing pipeline for plenoptic captures.

    Each command is one stage; `plenocli run CONFIG.yaml` chains them.

    \b
    Getting started, on a synthetic dual-pixel capture with its ground truth:
      plenocli simulate dualpixel -o sim
      plenocli decode sim/capture.dng -o sim/frames.tif
      plenocli bias sim/frames.tif -o sim/views.tif --preview sim/views.png
    then `plenocli COMMAND --help` for any stage (README.md walks through them all).
    """
