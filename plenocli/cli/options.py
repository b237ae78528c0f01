"""Options shared by every command, and the edge where library errors become one line."""

from __future__ import annotations

import functools
import sys

import click

from plenocli.errors import PlenocliError
from plenocli.progress import configure, working

output_opt = click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
                          help="Output file (written atomically).")
preview_opt = click.option("--preview", type=click.Path(dir_okay=False), default=None,
                           help="Also write a PNG preview here.")
input_arg = click.argument("input", type=click.Path(dir_okay=False))


def stage_command(func):
    """Add -v/-q/--debug and turn PlenocliError (and any crash) into one line, exit 1."""

    @click.option("-v", "--verbose", count=True, help="More messages (-v).")
    @click.option("-q", "--quiet", is_flag=True, help="Only errors.")
    @click.option("--debug", is_flag=True, help="Show tracebacks.")
    @functools.wraps(func)
    def wrapper(*args, verbose: int = 0, quiet: bool = False, debug: bool = False, **kwargs):
        configure(-1 if quiet else verbose)
        name = click.get_current_context().info_name or "plenocli"
        try:
            with working(name):
                return func(*args, **kwargs)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except PlenocliError as err:
            if debug:
                raise
            raise click.ClickException(str(err)) from err
        except KeyboardInterrupt:
            click.echo("plenocli: interrupted; no partial output was kept", err=True)
            sys.exit(130)
        except MemoryError as err:
            if debug:
                raise
            raise click.ClickException("out of memory; try a smaller crop or a machine with "
                                       "more RAM") from err
        except Exception as err:  # a bug: still one line, the traceback on request
            if debug:
                raise
            raise click.ClickException(f"internal error: {type(err).__name__}: {err} "
                                       "(run again with --debug for the traceback)") from err

    return wrapper
