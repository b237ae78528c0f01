"""``python -m plenocli``: the entry point, the one module outside cli/ that starts the command
line (relative import: everything else below the command line imports nothing of it)."""

from .cli.main import cli

cli()
