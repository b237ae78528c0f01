"""The make-style runner: skip up-to-date steps, rerun what an input or a parameter changed."""

import os
import re
import time
from pathlib import Path

import pytest

from plenocli.errors import ConfigError, OptionError
from plenocli.pipeline.config import load_config
from plenocli.pipeline.runner import plan, run_pipeline

ROOT = Path(__file__).resolve().parents[1]


def ran(decisions):
    return [d.step.name for d in decisions if d.run]


def test_runs_everything_then_nothing(project):
    steps = load_config(project)
    assert ran(run_pipeline(steps)) == ["decode_white", "bias_white", "decode", "bias", "flat",
                                        "develop"]
    out = project.parent.parent / "out" / "demo" / "dualpixel"
    assert (out / "views.tif").is_file() and (out / "views_A_B.png").is_file()
    assert ran(run_pipeline(load_config(project))) == []


def test_changed_input_reruns_it_and_what_depends_on_it(project):
    run_pipeline(load_config(project))
    capture = project.parent.parent / "fixtures" / "dualpixel" / "capture.dng"
    later = time.time() + 5
    os.utime(capture, (later, later))
    assert ran(run_pipeline(load_config(project))) == ["decode", "bias", "flat", "develop"]


def test_changed_parameter_reruns(project):
    run_pipeline(load_config(project))
    steps = load_config(project, ["bias.smooth=3"])
    assert ran(plan(steps)) == ["bias", "flat", "develop"]


def test_force_and_dry_run(project):
    decisions = run_pipeline(load_config(project), dry_run=True)
    assert len(ran(decisions)) == 6
    assert not (project.parent.parent / "out").exists()  # a dry run writes nothing
    run_pipeline(load_config(project))
    assert len(ran(plan(load_config(project), force=True))) == 6


def test_relative_paths_resolve_against_the_config_folder(project, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path / "fixtures")
    step = load_config(project)[0]
    assert Path(step.params["input"]) == (project.parent.parent / "fixtures" / "dualpixel"
                                          / "white.dng").resolve()


@pytest.mark.parametrize("text, message", [
    ("steps:\n  flat:\n    input: a.tif\n    output: b.tif\n    mediam: 3\n",
     "unknown key 'mediam' for stage flat (did you mean 'median'?)"),
    ("steps:\n  x:\n    stage: biass\n    input: a\n    output: b\n",
     "unknown stage 'biass' (did you mean 'bias'?)"),
    ("step:\n  bias: {}\n", "a config needs a 'steps:' mapping"),
    # audit 21 M3: an empty mapping and an empty name were told "needs a mapping", "quote it"
    ("steps: {}\n", "its 'steps:' mapping is empty"),
    ('steps: {"": {stage: bias, input: a, output: b}}\n', "step name '' must not be empty"),
    ("steps:\n  bias:\n    output: b.tif\n", "missing input"),
    ("steps: [unclosed\n", "not valid YAML"),
])
def test_config_errors_name_the_problem(tmp_path, text, message):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_config(path)


def test_unknown_top_level_key_and_bad_set(project):
    text = project.read_text().replace("description:", "descripton:")
    bad = project.with_name("bad.yaml")
    bad.write_text(text)
    with pytest.raises(ConfigError, match="did you mean 'description'"):
        load_config(bad)
    with pytest.raises(ConfigError, match="has no step 'bais'.*did you mean 'bias'"):
        load_config(project, ["bais.smooth=3"])
    for malformed in ("smooth=3", "bias.smooth"):  # audit 8 E3: a usage error (exit 2)
        with pytest.raises(OptionError, match="expected STEP.PARAM=VALUE"):
            load_config(project, [malformed])


def test_missing_input_that_no_step_makes(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("steps:\n  bias:\n    input: nowhere.tif\n    output: b.tif\n")
    with pytest.raises(ConfigError, match="nowhere.tif does not exist"):
        plan(load_config(path))


def _plenocli(*args, cwd):
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-c", "from plenocli.cli.main import cli; cli()",
                             *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def test_a_run_waits_for_another_run_writing_into_its_folders(tmp_path):
    """audit 10 P2: two `run --force` of one config each read a file the other then replaced,
    and left outputs whose records named inputs no longer on disk (3 runs in 6), both exit 0.
    A run holds the lock of the folders it writes into (as simulate does for a folder)."""
    import fcntl

    (tmp_path / "c.yaml").write_text(
        f"steps:\n  decode:\n    input: {ROOT / 'fixtures' / 'dualpixel' / 'white.dng'}\n"
        "    output: out/frames.tif\n  bias:\n    input: out/frames.tif\n"
        "    output: out/views.tif\n")
    (tmp_path / "out").mkdir()
    fd = os.open(tmp_path / "out", os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)   # another run, writing into out/
    try:
        run = _plenocli("run", "c.yaml", cwd=tmp_path)
        time.sleep(4)   # it has started (its message says it waits), and made nothing
        assert run.poll() is None and not (tmp_path / "out" / "frames.tif").exists()
    finally:
        os.close(fd)   # the other run ends
    _, err = run.communicate(timeout=120)
    assert run.returncode == 0, err
    assert "waiting for another run writing into out" in err
    assert (tmp_path / "out" / "views.tif").exists()


def test_a_run_takes_its_own_lock_again_for_a_folder_step(tmp_path):
    """simulate locks its folder's parent too: inside the run's lock of that parent it must not
    wait for itself."""
    (tmp_path / "c.yaml").write_text(
        "steps:\n  simulate:\n    kind: dualpixel\n    pixels: 32x48\n    output: out/sim\n"
        "  decode:\n    input: out/sim/capture.dng\n    output: out/frames.tif\n")
    run = _plenocli("run", "c.yaml", cwd=tmp_path)
    _, err = run.communicate(timeout=120)
    assert run.returncode == 0, err
    assert (tmp_path / "out" / "frames.tif").exists() and "waiting" not in err


def test_a_run_says_an_output_under_a_file_cannot_be_written(tmp_path, monkeypatch):
    """The run's lock makes the folders its outputs go into: an output under a file is said
    as the step's own check says it, not as the folder's making fails ('it exists already')."""
    from click.testing import CliRunner

    from plenocli.cli.main import cli

    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("a file")
    (tmp_path / "c.yaml").write_text(
        f"steps:\n  decode:\n    input: {ROOT / 'fixtures' / 'dualpixel' / 'white.dng'}\n"
        "    output: notes.txt/frames.tif\n")
    result = CliRunner().invoke(cli, ["run", "c.yaml"])
    assert result.exit_code == 1
    assert "notes.txt is a file, not a folder" in result.output, result.output
