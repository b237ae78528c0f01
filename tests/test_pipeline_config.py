"""Odd configs found by a black-box sweep of run / batch / --set / --print-make (issue 21): each is
run right or refused in one line, never a wrong file with exit 0."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError
from plenocli.pipeline import validators
from plenocli.pipeline.batch import run_batch
from plenocli.pipeline.config import load_config, read_template
from plenocli.pipeline.runner import plan

ROOT = Path(__file__).resolve().parents[1]
WHITE = ROOT / "fixtures" / "dualpixel" / "white.dng"
CAPTURE = ROOT / "fixtures" / "dualpixel" / "capture.dng"


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(result, *words):
    assert result.exit_code == 1, result.output
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:"), lines
    assert "internal error" not in lines[0] and "Traceback" not in result.output
    for word in words:
        assert word in lines[0], lines[0]


def write(folder: Path, text: str) -> Path:
    config = folder / "c.yaml"
    config.write_text(text.replace("{W}", str(WHITE)).replace("{C}", str(CAPTURE)))
    return config


def test_a_yaml_merge_key_is_yaml_not_a_duplicate(tmp_path):
    config = write(tmp_path, "steps:\n  decode:\n    <<: {camera: dng}\n    input: {W}\n"
                             "    output: w.tif\n")
    assert load_config(config)[0].params["camera"] == "dng"
    twice = write(tmp_path, "steps:\n  decode:\n    <<: {camera: dng}\n    camera: auto\n"
                            "    camera: dng\n    input: {W}\n    output: w.tif\n")
    with pytest.raises(ConfigError, match="given twice"):
        load_config(twice)


@pytest.mark.parametrize("name, words", [("~", "must be text"), ("5", "must be text"),
                                         ("''", "must not be empty")])
def test_a_step_name_must_be_text(tmp_path, name, words):
    config = write(tmp_path, f"steps:\n  {name}:\n    stage: decode\n    input: {{W}}\n"
                             "    output: w.tif\n")
    with pytest.raises(ConfigError, match=words):
        load_config(config)


@pytest.mark.parametrize("first, second", [("1", "true"), ("1", "1.0"), ("0", "false")])
def test_keys_one_in_python_but_two_in_yaml_are_not_called_a_duplicate(tmp_path, first, second):
    # audit 7 E1: `1:` and `true:` were refused as "key True is given twice"; neither is
    config = write(tmp_path, f"steps:\n  {first}: {{stage: decode, input: {{W}}, output: a.tif}}"
                             f"\n  {second}: {{stage: bias, input: a.tif, output: b.tif}}\n")
    with pytest.raises(ConfigError) as err:
        load_config(config)
    message = str(err.value)
    assert "given twice" not in message and f"key {second} " in message
    assert "quote the keys" in message
    with pytest.raises(ConfigError, match="given twice"):   # the same key twice still is
        load_config(write(tmp_path, f"steps:\n  {first}: {{stage: decode}}\n"
                                    f"  {first}: {{stage: bias}}\n"))


@pytest.mark.parametrize("key", ["input", "output"])
def test_a_nul_in_a_path_is_refused(tmp_path, key):
    value = '"a\\0b.tif"'
    text = "steps:\n  decode:\n    input: {W}\n    output: w.tif\n".replace(
        f"{key}: " + ("{W}" if key == "input" else "w.tif"), f"{key}: {value}")
    with pytest.raises(ConfigError, match="NUL"):
        load_config(write(tmp_path, text))


@pytest.mark.parametrize("overrides, words", [
    (["decode.ouput=x.tif"], "--set 'decode.ouput=x.tif': step 'decode': stage decode has no "
                             "parameter 'ouput' (did you mean 'output'?)"),
    (["decode.smooth=3"], "stage decode has no parameter 'smooth'"),
    (["decod.output=x.tif"], "has no step 'decod' (did you mean 'decode'?)"),
    (["decode.stage=bias"], "stage is not a parameter"),
    (["decode.output=x.tif", "decode.output=y.tif"], "already set by --set"),
])
def test_a_fault_in_the_set_words_is_a_usage_error_naming_the_set(tmp_path, overrides, words):
    # audit 10 E1: a misspelt --set key was blamed on the config ("c.yaml: step 'decode':
    # unknown key") with exit 1, while a malformed --set was a usage error
    config = write(tmp_path, "steps:\n  decode:\n    input: {W}\n    output: w.tif\n")
    result = invoke("run", config, *[w for item in overrides for w in ("--set", item)],
                    "--dry-run")
    assert result.exit_code == 2, result.output
    assert words in result.output and "unknown key" not in result.output


def test_set_cannot_change_a_steps_stage(tmp_path):
    config = write(tmp_path, "steps:\n  decode:\n    input: {W}\n    output: w.tif\n")
    with pytest.raises(ConfigError, match="stage is not a parameter"):
        load_config(config, ["decode.stage=bias"])


@pytest.mark.parametrize("command", ["run", "batch", "simulate"])
def test_an_empty_output_folder_is_a_usage_error(tmp_path, command, monkeypatch):
    monkeypatch.chdir(tmp_path)
    config = write(tmp_path, "steps:\n  decode:\n    input: {W}\n    output: \"{out}/w.tif\"\n")
    args = {"run": ["run", config, "--out", ""],
            "batch": ["batch", config, "--inputs", CAPTURE, "--out", ""],
            "simulate": ["simulate", "dualpixel", "-o", "", "--pixels", "32x48"]}[command]
    result = invoke(*args)
    assert result.exit_code == 2 and "the folder name is empty" in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


@pytest.mark.parametrize("command", ["run", "run-print-make", "batch"])
def test_out_is_a_usage_error_when_no_step_uses_it(tmp_path, command, monkeypatch):
    # own-2 (round 10): --out was ignored and the outputs went where the steps say
    monkeypatch.chdir(tmp_path)
    body = ('    input: "{capture}"\n    output: "o/{name}.tif"\n' if command == "batch"
            else "    input: {W}\n    output: w.tif\n")
    config = write(tmp_path, "steps:\n  decode:\n" + body)
    args = {"run": ["run", config, "--out", "elsewhere"],
            "run-print-make": ["run", config, "--print-make", "--out", "elsewhere"],
            "batch": ["batch", config, "--inputs", CAPTURE, "--out", "elsewhere", "-j", "1"]}
    result = invoke(*args[command])
    assert result.exit_code == 2, result.output
    assert "elsewhere: no step of" in result.output and "uses {out}" in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml"]


def test_an_out_key_no_step_uses_is_refused(tmp_path):
    config = write(tmp_path, "out: elsewhere\nsteps:\n  decode:\n    input: {W}\n"
                             "    output: w.tif\n")
    with pytest.raises(ConfigError, match=r"'out: elsewhere' fills \{out\}, which no step uses"):
        load_config(config)
    result = invoke("run", config, "--dry-run")
    one_line_error(result, "which no step uses")


@pytest.mark.parametrize("validator,kind", [
    (validators.InputFile(), "file"), (validators.OutputFile(".tif"), "file"),
    (validators.OutputFolder(), "folder")])
def test_every_path_is_checked_the_same_way(tmp_path, validator, kind):
    """Empty, or a folder where a file is meant (a file where a folder is): refused alike."""
    with pytest.raises(ValueError, match=f"the {kind} name is empty"):
        validator.convert("")
    (tmp_path / "f.tif").write_text("")
    wrong = tmp_path / ("f.tif" if kind == "folder" else "")
    with pytest.raises(ValueError, match="is a file" if kind == "folder" else "is a directory"):
        validator.convert(str(wrong))


def test_a_step_that_writes_no_file_always_runs(tmp_path):
    lens = ROOT / "configs" / "lenses" / "paper_table2.yaml"
    config = write(tmp_path, f"steps:\n  optics:\n    input: {lens}\n")
    assert [d.reason for d in plan(load_config(config))] == ["it writes no file"]


@pytest.mark.parametrize("name,shown", [("a=b.tif", "has '='"), ("~b.tif", "has '~'"),
                                        ("~root/b.tif", "has '~'"),
                                        ("m\\\\n.tif", "path m\\n.tif has '\\'"),
                                        ("a b.tif", "has a space")])
def test_print_make_refuses_names_make_misreads(tmp_path, name, shown, monkeypatch):
    """The character is named as typed (audit 24 M1: a backslash was shown as Python's '\\\\')."""
    monkeypatch.chdir(tmp_path)
    config = write(tmp_path, f"steps:\n  decode:\n    input: {{W}}\n    output: \"{name}\"\n")
    result = invoke("run", config, "--print-make")
    one_line_error(result, "make or the shell would misread")
    assert shown in result.output
    assert not result.stdout


def test_print_make_inputs_need_a_template(tmp_path):
    config = write(tmp_path, "steps:\n  decode:\n    input: {W}\n    output: w.tif\n")
    result = invoke("run", config, "--print-make", "--inputs", CAPTURE)
    assert result.exit_code == 2 and "not a batch template" in result.output


TEMPLATE = ("out: o\nsteps:\n"
            "  decode_white: {stage: decode, input: {W}, output: \"{out}/wf.tif\"}\n"
            "  decode: {input: \"{capture}\", output: \"{out}/{name}.tif\"}\n")


def test_a_capture_that_would_overwrite_a_shared_output_is_refused(tmp_path):
    config = write(tmp_path, TEMPLATE)
    captures = [tmp_path / "a.dng", tmp_path / "wf.dng"]  # the second writes o/wf.tif
    for c in captures:
        shutil.copy(CAPTURE, c)
    with pytest.raises(ConfigError, match="the output of shared step 'decode_white'"):
        run_batch(config, captures)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.dng", "c.yaml", "wf.dng"]
    result = invoke("run", config, "--print-make", "--inputs", captures[0], "--inputs",
                    captures[1])
    one_line_error(result, "would write", "wf.tif")
    template = read_template(config)
    template.check_captures_apart([str(captures[0])])  # the first alone is fine


def test_a_step_writing_into_another_steps_output_folder_is_refused(tmp_path):
    lens = ROOT / "configs" / "lenses" / "paper_table2.yaml"
    config = write(tmp_path, "steps:\n  simulate:\n    kind: dualpixel\n    pixels: 32x48\n"
                             f"    output: sim\n  optics:\n    input: {lens}\n"
                             "    json: sim/truth.json\n")  # would replace the simulated truth
    with pytest.raises(ConfigError, match="inside the folder that step 'simulate' fills"):
        load_config(config)


def test_a_step_writing_over_its_config_is_refused(tmp_path):
    lens = ROOT / "configs" / "lenses" / "paper_table2.yaml"
    config = tmp_path / "c.json"  # JSON is YAML
    config.write_text(f'{{"steps": {{"optics": {{"input": "{lens}", "json": "c.json"}}}}}}')
    before = config.read_bytes()
    result = invoke("run", config)
    one_line_error(result, "would write over this config")
    assert config.read_bytes() == before


@pytest.mark.parametrize("capture", ["..dng", "...dng"])
def test_a_capture_whose_name_leaves_the_output_folder_is_refused(tmp_path, capture):
    config = write(tmp_path, "out: o\nsteps:\n"
                             "  decode: {input: \"{capture}\", output: \"{out}/{name}/f.tif\"}\n")
    shutil.copy(CAPTURE, tmp_path / capture)
    (tmp_path / "f.tif").write_bytes(b"the user's file, where ...dng would write")
    result = invoke("batch", config, "--inputs", tmp_path / capture, "-j", "1")
    one_line_error(result, "cannot name a folder")
    assert (tmp_path / "f.tif").read_bytes().startswith(b"the user's file")
    assert not (tmp_path / "o").exists()
