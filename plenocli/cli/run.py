import click

from plenocli.cli import options
from plenocli.pipeline.validators import InputFile, OutputFolder


@click.command(short_help="Run a pipeline config (make-style).")
@click.argument("config", type=options.Declared(InputFile()))
@click.option("--force", is_flag=True, help="Rerun every step, even up-to-date ones.")
@click.option("--dry-run", is_flag=True, help="List what would run, run nothing.")
@click.option("--set", "overrides", multiple=True, metavar="STEP.PARAM=VALUE",
              help="Override a step parameter (repeatable), e.g. --set bias.smooth=9.")
@click.option("--out", type=options.Declared(OutputFolder()), default=None,
              help="Output root: fills {out} in the config (overrides its 'out:' key).")
@click.option("--print-make", is_flag=True,
              help="Print the pipeline as a Makefile fragment (stdout) instead of running it.")
@click.option("--inputs", "patterns", multiple=True, metavar="GLOB|FILE|@LIST",
              help="With --print-make and a batch template: the captures to write rules for.")
@options.stage_command
def run(config, force, dry_run, overrides, out, print_make, patterns):
    """Run the steps of CONFIG in order; a step is skipped when the record kept beside each of
    its outputs (.NAME.plenocli.json) shows it was made with the same parameters from the
    inputs as they are now, and the output is unchanged since.

    With --print-make, print make rules instead (targets = outputs, prerequisites = inputs and
    CONFIG, recipe = the plenocli command); paths are relative to the current folder.

    \b
    Example:
      plenocli run configs/demo_dualpixel.yaml --set bias.smooth=9 --dry-run
      plenocli run configs/demo_dualpixel.yaml --print-make > demo.mk && make -f demo.mk -j2
    """
    from plenocli.pipeline.config import load_config, read_template

    if print_make and (dry_run or force):
        raise click.UsageError(f"--print-make prints the rules and runs nothing; leave out "
                               f"{'--dry-run' if dry_run else '--force'}")
    if patterns and not print_make:
        raise click.UsageError("--inputs goes with --print-make; to run a batch of captures "
                               "use plenocli batch CONFIG --inputs ...")
    if print_make:
        import shlex
        import sys

        from plenocli.pipeline.makefile import make_fragment

        template = read_template(config, overrides)
        if patterns and not template.per_capture_steps():
            raise click.UsageError(f"--inputs: {config} is not a batch template (no step uses "
                                   "{capture} or {name}); leave --inputs out")
        if patterns:
            from plenocli.pipeline.captures import expand_inputs

            captures = [str(c) for c in expand_inputs(patterns, template=template, out=out)]
            template.check_captures_apart(captures, out=out)
            steps = template.steps(out=out, only="shared")
            for capture in captures:
                steps += template.steps(capture=capture, out=out, only="per-capture")
        else:
            steps = template.steps(out=out)  # a batch template without --inputs: says so
        command = "plenocli run " + " ".join(shlex.quote(a) for a in sys.argv[2:])
        click.echo(make_fragment(steps, config, command=command), nl=False)
        return
    from plenocli.pipeline.runner import run_pipeline

    if out is None:
        steps = load_config(config, overrides)
    else:
        steps = read_template(config, overrides).steps(out=out)
    run_pipeline(steps, force=force, dry_run=dry_run, locked=True)
