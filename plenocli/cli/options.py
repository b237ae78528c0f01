"""Options shared by every command, and the edge where library errors become one line."""

from __future__ import annotations

import functools
import math
import sys
import warnings

import click

from plenocli.errors import PlenocliError
from plenocli.progress import configure, working

output_opt = click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
                          help="Output file (written atomically).")
preview_opt = click.option("--preview", type=click.Path(dir_okay=False), default=None,
                           help="Also write a PNG preview here.")
input_arg = click.argument("input", type=click.Path(dir_okay=False))


class FiniteFloat(click.ParamType):
    """A finite float, optionally bounded: NaN and infinities are refused (click's FloatRange
    lets NaN through, since every comparison with NaN is false).

    ``min_open``/``max_open`` make a bound exclusive, e.g. ``FiniteFloat(min=0, min_open=True)``
    for a strictly positive value.
    """

    name = "float"

    def __init__(self, min: float | None = None, max: float | None = None, *,
                 min_open: bool = False, max_open: bool = False):
        self.min, self.max, self.min_open, self.max_open = min, max, min_open, max_open

    def convert(self, value, param, ctx):
        if isinstance(value, bool):
            self.fail(f"{value!r} is not a number", param, ctx)
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        low_bad = self.min is not None and (number <= self.min if self.min_open
                                            else number < self.min)
        high_bad = self.max is not None and (number >= self.max if self.max_open
                                             else number > self.max)
        if low_bad or high_bad:
            self.fail(f"{number:g} is not in the range {self._describe()}", param, ctx)
        return number

    def _describe(self) -> str:
        parts = []
        if self.min is not None:
            parts.append(f"x{'>' if self.min_open else '>='}{self.min:g}")
        if self.max is not None:
            parts.append(f"x{'<' if self.max_open else '<='}{self.max:g}")
        return " and ".join(parts) or "of finite numbers"

    def __repr__(self) -> str:
        return f"FiniteFloat({self._describe()})"


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
            with working(name), warnings.catch_warnings():
                if not debug:  # numpy's RuntimeWarnings print source lines, not news
                    warnings.simplefilter("ignore", RuntimeWarning)
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
