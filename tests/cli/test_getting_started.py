"""The getting-started lines of `plenocli --help` run as printed, in a fresh folder."""

from __future__ import annotations

import shlex

from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio


def test_the_getting_started_commands_of_the_help_run(tmp_path, monkeypatch):
    text = CliRunner().invoke(cli, ["--help"]).output
    lines = text.split("Getting started", 1)[1].splitlines()
    commands = [shlex.split(ln) for ln in lines if ln.strip().startswith("plenocli ")]
    assert [c[1] for c in commands] == ["simulate", "decode", "bias"]
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        result = CliRunner().invoke(cli, argv[1:])
        assert result.exit_code == 0, (argv, result.output)
    views, meta = tiffio.read_image(tmp_path / "sim" / "views.tif")
    assert meta["views"] == ["A", "B", "S"] and (tmp_path / "sim" / "views.png").stat().st_size
