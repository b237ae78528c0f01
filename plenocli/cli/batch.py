import click

from plenocli.cli import options
from plenocli.pipeline.validators import MAX_TIMEOUT_S, FiniteFloat, InputFile, Int, OutputFolder


@click.command(short_help="Run a pipeline template over many captures, in parallel.")
@click.argument("config", type=options.Declared(InputFile()))
@click.option("--inputs", "patterns", multiple=True, required=True, metavar="GLOB|FILE|@LIST",
              help="Captures: a quoted glob, a file, or @list.txt (one path a line); repeatable.")
@click.option("-j", "--jobs", cls=options.DeclaredOption, type=options.Declared(Int(min=1)),
              default=None,
              help="Worker processes on this machine [default: number of CPUs]; not with "
                   "--scheduler.")
@click.option("--out", type=options.Declared(OutputFolder()), default=None,
              help="Output root: fills {out} in the config (overrides its 'out:' key).")
@click.option("--force", is_flag=True, help="Rerun every step, even up-to-date ones.")
@click.option("--dry-run", is_flag=True, help="Say what would run, run nothing.")
@click.option("--set", "overrides", multiple=True, metavar="STEP.PARAM=VALUE",
              help="Override a step parameter (repeatable), e.g. --set bias.smooth=9.")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Send the captures to this dask.distributed scheduler (tcp://host:8786) "
                   "instead of local processes; needs pip install 'plenocli[dask]'.")
@click.option("--timeout", type=options.Declared(FiniteFloat(min=0, max=MAX_TIMEOUT_S,
                                                            min_open=True, max_open=True)),
              default=None, metavar="SECONDS", help="Stop a capture that runs longer than "
              "this in its worker and report it as failed (under 10000000 s).")
@options.stage_command
def batch(config, patterns, jobs, out, force, dry_run, overrides, scheduler, timeout):
    """Run the pipeline template CONFIG over many captures.

    In CONFIG, per-capture steps read "{capture}" and write under "{out}/{name}/" ({name} is the
    capture's file name without suffix); steps without {capture}/{name} (white image,
    calibration) run once and every capture reuses them. Up-to-date outputs are skipped, so a
    rerun after a failure only redoes what is missing (a glob's matches that the batch writes
    are left out of the captures). Prints a table (done / skipped / failed with the reason);
    exit status 1 when a capture failed.

    \b
    Example:
      plenocli batch configs/batch_dualpixel.yaml --inputs 'shoot/*.dng' --out out/shoot -j 2
    """
    import logging
    import os

    from plenocli.errors import PlenocliError
    from plenocli.pipeline.batch import format_summary, run_batch
    from plenocli.pipeline.captures import expand_inputs
    from plenocli.pipeline.config import read_template
    from plenocli.progress import log

    if scheduler and jobs is not None:  # a Dask cluster's own workers run the captures
        raise click.UsageError("-j/--jobs sets worker processes on this machine; with "
                               "--scheduler the cluster's workers run the captures: leave -j out")
    if jobs is None:
        jobs = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    # SIGTERM and Ctrl-C: the edge (options.stage_command) stops the workers and says so
    captures = expand_inputs(patterns, template=lambda: read_template(config, overrides),
                             out=out)
    report = run_batch(config, captures, overrides=overrides, out=out,
                       force=force, dry_run=dry_run, jobs=jobs or 1, scheduler=scheduler,
                       timeout=timeout)
    if log.isEnabledFor(logging.INFO):  # -q keeps only the failures
        click.echo(format_summary(report), err=True)
    for failure in report.failed:
        click.echo(f"failed: {failure.capture}: {failure.detail}", err=True)
    if report.failed:
        raise PlenocliError(f"{len(report.failed)} of {len(report.results)} captures failed "
                            "(see above); fix them and run the same command again")
