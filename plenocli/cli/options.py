"""Options shared by every command, and the edge where library errors become one line."""

from __future__ import annotations

import contextlib
import functools
import signal
import sys
import warnings

import click
from click.core import ParameterSource

from plenocli.errors import (
    OptionError,
    PlenocliError,
    Terminated,
    check_terminated,
    clear_terminated,
    interrupt_note,
    os_error_message,
    raise_terminated,
)
from plenocli.pipeline.params import Param
from plenocli.pipeline.validators import Validator
from plenocli.progress import configure, printable, working


class Declared(click.ParamType):
    """The one adapter from a validator (:mod:`plenocli.pipeline.validators`) to click: its
    ValueError becomes click's usage error (exit 2, "Invalid value for '--x': ...")."""

    def __init__(self, validator: Validator):
        self.validator = validator
        self.name = validator.name

    def get_metavar(self, param, ctx):
        choices = self.validator.choices
        if choices is None:
            return None
        if param.required and param.param_type_name == "argument":
            return "{" + "|".join(choices) + "}"
        return "[" + "|".join(choices) + "]"

    def convert(self, value, param, ctx):
        if isinstance(value, str) and _is_option_of(ctx, value) and \
                getattr(param, "param_type_name", None) == "option":
            # `--linear -o out.tif`: the option swallowed the next one as its value
            self.fail(f"got the option {value!r} as its value; give {param.opts[-1]} its own "
                      f"value ({param.opts[-1]} {param.make_metavar(ctx)})", param, ctx)
        try:
            return self.validator.convert(value)
        except ValueError as err:
            self.fail(str(err), param, ctx)


def _is_option_of(ctx: click.Context | None, word: str) -> bool:
    """Whether ``word`` is one of the command's own option names (-o, --output, --help)."""
    if ctx is None or not word.startswith("-"):
        return False
    names = {*ctx.help_option_names}
    for p in ctx.command.params:
        names.update(p.opts, p.secondary_opts)
    return word in names


class DeclaredOption(click.Option):
    """An option whose --help shows its validator's range, as click's IntRange does."""

    def get_help_extra(self, ctx):
        extra = super().get_help_extra(ctx)
        if self.type.validator.range_help:
            extra["range"] = self.type.validator.range_help
        return extra


def declared(params: tuple[Param, ...]):
    """Decorator: the click arguments and options of a stage's declared ``params``, in order."""

    def decorate(func):
        for p in reversed(params):
            kind = Declared(p.type)
            if p.positional:
                func = click.argument(p.name, type=kind, required=p.required,
                                      nargs=-1 if p.multiple else 1, metavar=p.metavar)(func)
            elif p.is_flag:
                func = click.option(*p.flags, p.name, is_flag=True, default=bool(p.default),
                                    help=p.help)(func)
            else:
                given = {} if p.default is None else {"default": p.default, "show_default": True}
                func = click.option(*p.flags, p.name, cls=DeclaredOption, type=kind,
                                    required=p.required, multiple=p.multiple, metavar=p.metavar,
                                    help=p.help, **given)(func)
        return func

    return decorate


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
        except OptionError as err:
            if debug:
                raise
            raise click.UsageError(printable(str(err))) from err
        except PlenocliError as err:
            if debug:
                raise
            raise click.ClickException(printable(" ".join(str(err).split()))) from err
        except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM as Terminated
            what = "terminated" if isinstance(err, Terminated) else "interrupted"
            note = interrupt_note(err)
            click.echo(f"plenocli: {what}; no partial output was kept"
                       + (f"; but {note}" if note else ""), err=True)
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
    """The registered stage's check across parameters, then its guard (output checks, outputs
    landing together); none for a command that is not a stage."""
    from plenocli.pipeline.registry import get_stages

    stage = get_stages().get(name)
    if stage is None:
        return contextlib.nullcontext()
    ctx = click.get_current_context()
    stage.check(params, {key for key in params
                         if ctx.get_parameter_source(key) not in (None, ParameterSource.DEFAULT)})
    return stage.guard(params)


@contextlib.contextmanager
def _terminate_on_sigterm():
    """Turn SIGTERM into an exception, so temporaries are removed as on Ctrl-C. When the
    exception is lost (raised inside a ``__del__`` or weakref callback), no traceback is
    printed and the stage still ends as terminated before any output lands
    (:func:`plenocli.errors.check_terminated`)."""

    def handler(signum, frame):
        raise_terminated()

    def unraisable(info):
        if not isinstance(info.exc_value, Terminated):
            previous_hook(info)

    clear_terminated()
    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread (e.g. a Dask worker): leave signals alone
        yield
        return
    previous_hook, sys.unraisablehook = sys.unraisablehook, unraisable
    try:
        yield
        check_terminated()
    finally:
        signal.signal(signal.SIGTERM, previous)
        sys.unraisablehook = previous_hook
