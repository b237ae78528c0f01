"""Options shared by every command, and the edge where library errors become one line."""

from __future__ import annotations

import contextlib
import functools
import math
import os
import signal
import sys
import warnings

import click

from plenocli.errors import PlenocliError, Terminated, os_error_message
from plenocli.progress import configure, working

TIFF = (".tif", ".tiff")


class OutputFile(click.Path):
    """A file a command writes, whose name must end in one of ``suffixes`` (any case): a name
    saying another format (a preview named .jpg, frames named .png) would hold what it does not
    say, and the make-style runner reads outputs by their suffix."""

    def __init__(self, *suffixes: str):
        super().__init__(dir_okay=False)
        self.suffixes = suffixes

    def convert(self, value, param, ctx):
        value = super().convert(value, param, ctx)
        if os.path.splitext(str(value))[1].lower() not in self.suffixes:
            self.fail(f"{str(value)!r} is written as {self.suffixes[0][1:].upper()}; give a name "
                      f"ending in {' or '.join(self.suffixes)}", param, ctx)
        return value


class InputFile(click.Path):
    """A file a command reads. A folder is a usage error (exit 2), like any value of the wrong
    kind; whether the file is there and can be read is the reader's to say (exit 1 with the
    reason), as for a file that turns out to be damaged."""

    def __init__(self):
        super().__init__(dir_okay=False, readable=False)

    def convert(self, value, param, ctx):
        if str(value) == "":
            self.fail("the file name is empty", param, ctx)
        return super().convert(value, param, ctx)


class OutputFolder(click.Path):
    """A folder a command writes into (made when missing); an empty name would be the current
    folder, which no one means."""

    def __init__(self):
        super().__init__(file_okay=False)

    def convert(self, value, param, ctx):
        if str(value) == "":
            self.fail("the folder name is empty", param, ctx)
        return super().convert(value, param, ctx)


def output_option(*suffixes: str):
    """The -o/--output option of a command whose output is a file of one of ``suffixes``
    (any file name when none is given: the command checks it)."""
    return click.option("-o", "--output", required=True,
                        type=OutputFile(*suffixes) if suffixes else click.Path(dir_okay=False),
                        help="Output file (written atomically).")


output_opt = output_option(*TIFF)
preview_opt = click.option("--preview", type=OutputFile(".png"), default=None,
                           help="Also write a PNG preview here.")
input_arg = click.argument("input", type=InputFile())


class RowsCols(click.ParamType):
    """A size ROWSxCOLS of positive whole numbers, e.g. 2000x2000 (kept as that text)."""

    name = "ROWSxCOLS"

    def convert(self, value, param, ctx):
        text = str(value).strip().lower()
        rows, sep, cols = text.partition("x")
        if not (sep and rows.isdigit() and cols.isdigit() and int(rows) > 0 and int(cols) > 0):
            self.fail(f"{value!r} is not ROWSxCOLS (e.g. 2000x2000)", param, ctx)
        return f"{int(rows)}x{int(cols)}"


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
    """Add -v/-q/--debug and make the command's edge: outputs checked and landed together
    (for a registered stage), SIGTERM handled like Ctrl-C, and every error one line, exit 1."""

    @click.option("-v", "--verbose", count=True, help="More messages (-v).")
    @click.option("-q", "--quiet", is_flag=True, help="Only errors.")
    @click.option("--debug", is_flag=True, help="Show tracebacks.")
    @functools.wraps(func)
    def wrapper(*args, verbose: int = 0, quiet: bool = False, debug: bool = False, **kwargs):
        configure(-1 if quiet else verbose)
        name = click.get_current_context().info_name or "plenocli"
        try:
            with _terminate_on_sigterm(), warnings.catch_warnings(), working(name):
                if not debug:
                    warnings.simplefilter("ignore")  # library chatter; errors say what matters
                with _stage_edge(name, kwargs):
                    return func(*args, **kwargs)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise
        except PlenocliError as err:
            if debug:
                raise
            raise click.ClickException(" ".join(str(err).split())) from err  # one line
        except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM as Terminated
            what = "terminated" if isinstance(err, Terminated) else "interrupted"
            click.echo(f"plenocli: {what}; no partial output was kept", err=True)
            sys.exit(143 if isinstance(err, Terminated) else 130)
        except MemoryError as err:
            if debug:
                raise
            raise click.ClickException("out of memory; try a smaller crop or a machine with "
                                       "more RAM") from err
        except OSError as err:
            if debug:
                raise
            raise click.ClickException(os_error_message(err)) from err
        except Exception as err:  # a bug: still one line, the traceback on request
            if debug:
                raise
            raise click.ClickException(f"internal error: {type(err).__name__}: "
                                       f"{' '.join(str(err).split())} (run again with --debug "
                                       "for the traceback; please report it)") from err

    return wrapper


def _stage_edge(name: str, params: dict):
    """The registered stage's guard (output checks, outputs landing together), if any."""
    from plenocli.pipeline.registry import get_stages

    stage = get_stages().get(name)
    return stage.guard(params) if stage is not None else contextlib.nullcontext()


@contextlib.contextmanager
def _terminate_on_sigterm():
    """Turn SIGTERM into an exception, so temporaries are removed as on Ctrl-C."""

    def handler(signum, frame):
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. a Dask worker): leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
