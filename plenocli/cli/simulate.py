import click

from plenocli.cli import options
from plenocli.synth import KIND_NAMES


@click.command(short_help="Write synthetic captures with ground truth.",
               epilog="KIND is one of: " + ", ".join(KIND_NAMES) + ".")
@click.argument("kind", metavar="KIND", type=click.Choice(KIND_NAMES))
@click.option("-o", "--output", required=True, type=options.OutputFolder(),
              help="Folder for the capture files and truth.json.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Random seed.")
@click.option("--pixels", default=None, help="Sensor size, ROWSxCOLS or one number.")
@click.option("--rays", type=click.IntRange(min=1), default=None,
              help="Rays per pixel (optical kinds).")
@click.option("--no-prisms", is_flag=True, default=None, help="Remove the prisms (optical kinds).")
@click.option("--param", multiple=True, metavar="KEY=VALUE",
              help="Another option of the kind (repeatable), e.g. --param noise=0.")
@options.stage_command
def simulate(**params):
    """Write a synthetic capture set of KIND into a folder, with its ground truth.

    \b
    Example:
      plenocli simulate dualpixel -o fixtures/dualpixel --seed 1
    """
    from plenocli.pipeline.stages.simulate import run

    run(**params)
