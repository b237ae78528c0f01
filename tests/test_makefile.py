"""`plenocli run --print-make`: make rules that build the same outputs, incrementally."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError
from plenocli.pipeline.batch import run_batch
from plenocli.pipeline.config import load_config
from plenocli.pipeline.makefile import make_fragment
from tests.test_batch import concrete_config, make_shoot, pixels

ROOT = Path(__file__).resolve().parents[1]
needs_make = pytest.mark.skipif(shutil.which("make") is None, reason="GNU make not installed")


def _make(folder: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(["make", "-f", "pipeline.mk", *args,
                           f"PLENOCLI={sys.executable} -m plenocli"],
                          cwd=folder, env=env, capture_output=True, text=True, timeout=120)


@needs_make
def test_make_builds_the_batch_outputs_then_does_nothing(tmp_path, monkeypatch):
    config, captures = make_shoot(tmp_path, 4, corrupt=None)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["run", str(config), "--print-make", "--out", "mk",
                                      "--inputs", str(tmp_path / "captures" / "*.dng")])
    assert result.exit_code == 0, result.output
    (tmp_path / "pipeline.mk").write_text(result.stdout)
    built = _make(tmp_path, "-j2")
    assert built.returncode == 0, built.stderr
    run_batch(config, captures, out=tmp_path / "batch", jobs=1)
    for c in captures:
        for name in ("frames.tif", "biased.tif", "views.tif"):
            np.testing.assert_array_equal(pixels(tmp_path / "mk" / c.stem / name),
                                          pixels(tmp_path / "batch" / c.stem / name))
    assert _make(tmp_path, "-q").returncode == 0  # everything up to date
    # the recipes wrote the runner's records: plenocli batch agrees that nothing is to do
    again = run_batch(config, captures, out=tmp_path / "mk", jobs=1)
    assert [r.status for r in again.results] == ["skipped"] * 4
    assert [d.run for d in again.shared] == [False] * len(again.shared)
    again = _make(tmp_path)
    assert "Nothing to be done" in again.stdout and "-m plenocli" not in again.stdout
    # touching one capture rebuilds that capture only
    os.utime(captures[2])
    rebuilt = _make(tmp_path, "-j2")
    lines = [ln for ln in rebuilt.stdout.splitlines() if " -m plenocli" in ln]
    assert len(lines) == 3 and all("shot02" in ln for ln in lines)


def test_fragment_rules(tmp_path):
    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    single = concrete_config(tmp_path, captures[0], tmp_path / "o")
    text = single.read_text().replace("    gain: ", "    preview: o/view.png\n    gain: ")
    single.write_text(text)
    fragment = make_fragment(load_config(single), single, base=tmp_path)
    assert "PLENOCLI ?= plenocli" in fragment
    assert ("o/shot00/views.tif single/o/view.png &: o/shot00/biased.tif o/gain.tif "
            "single/shot00.yaml\n\t$(PLENOCLI) flat o/shot00/biased.tif --preview="
            "single/o/view.png --gain=o/gain.tif --output=o/shot00/views.tif") in fragment
    assert ("o/shot00/frames.tif : captures/shot00.dng single/shot00.yaml\n"
            "\t$(PLENOCLI) decode captures/shot00.dng --output=o/shot00/frames.tif") in fragment


def test_fragment_refuses_paths_make_cannot_hold(tmp_path):
    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    single = concrete_config(tmp_path, captures[0], tmp_path / "my out")
    with pytest.raises(ConfigError, match="has a space, which make or the shell"):
        make_fragment(load_config(single), single, base=tmp_path)


def test_print_make_of_a_template_needs_inputs(tmp_path):
    config, _ = make_shoot(tmp_path, 1, corrupt=None)
    result = CliRunner().invoke(cli, ["run", str(config), "--print-make"])
    assert result.exit_code == 1 and "give a capture" in result.stderr


def test_inputs_without_print_make_is_a_usage_error(tmp_path):
    config, _ = make_shoot(tmp_path, 1, corrupt=None)
    result = CliRunner().invoke(cli, ["run", str(config), "--inputs", "x.dng"])
    assert result.exit_code == 2 and "plenocli batch" in result.stderr
