import inspect

import click

from plenocli.cli import options
from plenocli.errors import ConfigError
from plenocli.progress import log


def _kind_names():
    from plenocli.synth import kinds

    return sorted(kinds())


@click.command(short_help="Write synthetic captures with ground truth.",
               epilog="KIND is one of: " + ", ".join(_kind_names()) + ".")
@click.argument("kind", metavar="KIND", type=click.Choice(_kind_names()))
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False),
              help="Folder for the capture files and truth.json.")
@click.option("--seed", type=click.IntRange(min=0),
              default=0, show_default=True, help="Random seed.")
@click.option("--pixels", default=None, help="Sensor size, ROWSxCOLS or one number.")
@click.option("--rays", type=click.IntRange(min=1),
              default=None, help="Rays per pixel (optical kinds).")
@click.option("--no-prisms", is_flag=True, default=None, help="Remove the prisms (optical kinds).")
@click.option("--param", "extra", multiple=True, metavar="KEY=VALUE",
              help="Another option of the kind (repeatable), e.g. --param noise=0.")
@options.stage_command
def simulate(kind, output, extra, **given):
    """Write a synthetic capture set of KIND into a folder, with its ground truth.

    \b
    Example:
      plenocli simulate dualpixel -o fixtures/dualpixel --seed 1
    """
    import yaml

    from plenocli.synth import kinds

    writer = kinds()[kind]
    kwargs = {k: v for k, v in given.items() if v is not None}
    if "pixels" in kwargs and kwargs["pixels"].isdigit():  # one number, else ROWSxCOLS
        kwargs["pixels"] = int(kwargs["pixels"])
    for item in extra:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"--param {item!r}: expected KEY=VALUE")
        kwargs[key.replace("-", "_")] = yaml.safe_load(value)
    accepted = inspect.signature(writer).parameters
    for key in kwargs:
        if key not in accepted:
            names = ", ".join(k for k in accepted if k != "out_dir")
            raise ConfigError(f"simulate {kind} does not take {key!r}; it takes: {names}")
    try:
        writer(output, **kwargs)
    except (ValueError, TypeError) as err:
        raise ConfigError(f"simulate {kind}: {err}") from err
    log.info("simulate %s: wrote %s", kind, output)
