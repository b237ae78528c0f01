"""The command group: lazy loading, pipeline order, short help strings that match."""

from __future__ import annotations

import importlib
import subprocess
import sys

import click
from click.testing import CliRunner

from plenocli.cli.main import COMMANDS, cli


def test_every_listed_command_exists_with_the_same_short_help():
    for name, short_help in COMMANDS.items():
        command = getattr(importlib.import_module(f"plenocli.cli.{name}"), name)
        assert isinstance(command, click.Command)
        assert command.short_help == short_help, name


def test_help_lists_commands_in_pipeline_order():
    result = CliRunner().invoke(cli, ["--help"])
    assert result.exit_code == 0
    listed = [line.split()[0] for line in result.output.split("Commands:")[1].splitlines()
              if line.strip()]
    assert listed == list(COMMANDS)


def test_help_imports_no_command_module():
    code = ("import sys; from plenocli.cli.main import cli\n"
            "try:\n    cli(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in sys.modules if m.startswith(('plenocli.cli.', 'numpy', "
            "'scipy', 'cv2', 'numba', 'tifffile')) and m != 'plenocli.cli.main']\n"
            "print(','.join(heavy), file=sys.stderr)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stderr.strip() == ""


def test_stage_help_loads_neither_numba_nor_opencv():
    """A declaration takes its choices from light model modules, not from the kernels."""
    code = ("import sys; from plenocli.cli.main import cli\n"
            "for name in sys.argv[1:]:\n"
            "    try:\n        cli([name, '--help'])\n    except SystemExit:\n        pass\n"
            "heavy = [m for m in sys.modules if m.split('.')[0] in ('numba', 'cv2')]\n"
            "print(','.join(heavy), file=sys.stderr)")
    names = [n for n in COMMANDS if n != "simulate"]
    done = subprocess.run([sys.executable, "-c", code, *names], capture_output=True, text=True,
                          check=True)
    assert done.stderr.strip() == ""


def test_unknown_command_is_a_usage_error():
    result = CliRunner().invoke(cli, ["no-such-stage"])
    assert result.exit_code == 2
    assert "No such command" in result.output


def test_every_stage_command_is_built_from_its_declaration():
    from plenocli.pipeline.registry import get_stages

    for name, stage in get_stages().items():
        command = cli.get_command(None, name)
        built = [p.name for p in command.params if p.name not in ("verbose", "quiet", "debug")]
        assert built == [p.name for p in stage.params], name
        result = CliRunner().invoke(cli, [name])  # a required argument or option left out
        assert result.exit_code == 2 and "Missing" in result.output, (name, result.output)
