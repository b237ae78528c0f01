import click

from plenocli.cli import options


@click.command(short_help="Run a pipeline config (make-style).")
@click.argument("config", type=click.Path(dir_okay=False))
@click.option("--force", is_flag=True, help="Rerun every step, even up-to-date ones.")
@click.option("--dry-run", is_flag=True, help="List what would run, run nothing.")
@click.option("--set", "overrides", multiple=True, metavar="STEP.PARAM=VALUE",
              help="Override a step parameter (repeatable), e.g. --set bias.smooth=9.")
@options.stage_command
def run(config, force, dry_run, overrides):
    """Run the steps of CONFIG in order; a step whose outputs are newer than its inputs and
    whose parameters are unchanged is skipped.

    \b
    Example:
      plenocli run configs/demo_dualpixel.yaml --set bias.smooth=9 --dry-run
    """
    from plenocli.pipeline.config import load_config
    from plenocli.pipeline.runner import run_pipeline

    run_pipeline(load_config(config, overrides), force=force, dry_run=dry_run)
