import click

from plenocli.cli import options
from plenocli.pipeline.schema import simulate as schema
from plenocli.synth import KIND_NAMES


@click.command(short_help="Write synthetic captures with ground truth.",
               epilog="KIND is one of: " + ", ".join(KIND_NAMES) + ".")
@options.declared(schema.PARAMS)
@options.stage_command
def simulate(**params):
    """Write a synthetic capture set of KIND into a folder, with its ground truth.

    \b
    Example:
      plenocli simulate dualpixel -o fixtures/dualpixel --seed 1
    """
    from plenocli.pipeline.stages.simulate import run

    run(**params)
