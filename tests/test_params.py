"""One parameter path: the shell, a YAML step and --set give the same checks and the same
resolved parameters; the runner reruns a step whose resolved parameters changed."""

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError
from plenocli.io.tiffio import read_meta
from plenocli.pipeline.config import load_config
from plenocli.pipeline.registry import get_stages
from plenocli.pipeline.runner import plan, run_pipeline

ROOT = Path(__file__).resolve().parents[1]

# (stage, option, value as a YAML scalar would give it, value as typed in a shell)
BAD_VALUES = [
    ("bias", "smooth", -3, "-3"),
    ("bias", "smooth", 1.5, "1.5"),
    ("bias", "smooth", "abc", "abc"),
    ("bias", "guard", -5, "-5"),
    ("bias", "crop", 12345, "12345"),
    ("bias", "overscan", "sideways", "sideways"),
    ("decode", "black", float("nan"), "nan"),
    ("decode", "white", -5, "-5"),
    ("flat", "percentile", 101, "101"),
    ("flat", "floor", float("inf"), "inf"),
    ("refocus", "s", 0, "0"),
    ("refocus", "g", "abc", "abc"),
    ("refocus", "view", "sideways", "sideways"),
    ("refocus", "mask-width", -1, "-1"),
    ("stitch", "overlap", 1.5, "1.5"),
    ("optics", "sensor-mm", float("nan"), "nan"),
    ("optics", "prism-n", 1, "1"),
    ("sai", "cfa-layout", "quad", "quad"),
    ("decode", "cfa", "RGBG", "RGBG"),
    ("develop", "quality", 101, "101"),
    ("develop", "wb", "1e308,1,1", "1e308,1,1"),
    ("depth", "g", "8", "8"),
    ("unmix", "regularise", 1.5, "1.5"),
    ("stitch", "layout", "3x3", "3x3"),
]


def _argv(stage: str, option: str, value: str) -> list[str]:
    required = {"refocus": ["--grid", "g.yaml"], "unmix": ["--mixing", "m.tif"]}.get(stage, [])
    out = [] if stage == "optics" else ["-o", "out.tif"]
    return [stage, "in.tif", *out, *required, f"--{option}", value]


def _config(tmp_path: Path, stage: str, extra: str = "") -> Path:
    body = {"refocus": "    grid: g.yaml\n", "unmix": "    mixing: m.tif\n"}.get(stage, "")
    out = "" if stage == "optics" else "    output: out.tif\n"
    path = tmp_path / "c.yaml"
    key = "inputs" if stage in ("stitch", "unmix") else "input"
    path.write_text(f"steps:\n  {stage}:\n    {key}: in.tif\n{out}{body}{extra}")
    return path


@pytest.mark.parametrize("stage, option, yaml_value, shell_value", BAD_VALUES)
def test_a_bad_value_fails_the_same_way_everywhere(tmp_path, stage, option, yaml_value,
                                                   shell_value):
    result = CliRunner().invoke(cli, _argv(stage, option, shell_value))
    assert result.exit_code == 2
    shell_message = result.output.strip().splitlines()[-1].removeprefix("Error: ")

    config = _config(tmp_path, stage, f"    {option}: {yaml_value!r}\n".replace("nan", ".nan")
                     .replace("inf", ".inf"))
    with pytest.raises(ConfigError) as from_yaml:
        load_config(config)
    with pytest.raises(ConfigError) as from_set:
        load_config(_config(tmp_path, stage), [f"{stage}.{option}={shell_value}"])
    for err in (from_yaml.value, from_set.value):
        assert str(err).endswith(shell_message), (str(err), shell_message)
        assert f"step '{stage}'" in str(err)
    assert not list(tmp_path.glob("out*"))


def test_resolved_parameters_include_every_default(tmp_path):
    step = load_config(_config(tmp_path, "bias", "    smooth: 9\n"))[0]
    assert step.params["smooth"] == 9
    assert step.params["guard"] == 2 and step.params["overscan"] == "auto"
    assert set(step.params) == set(get_stages()["bias"].parameters())
    assert step.given == ("input", "output", "smooth")


def test_set_values_are_parsed_like_shell_words(tmp_path):
    step = load_config(_config(tmp_path, "bias"), ["bias.smooth=9", "bias.crop=20X30"])[0]
    assert step.params["smooth"] == 9 and step.params["crop"] == "20x30"


def test_a_yaml_list_is_the_comma_separated_word(tmp_path):
    listed = load_config(_config(tmp_path, "refocus", "    g: [2, 3.5]\n"))[0]
    typed = load_config(_config(tmp_path, "refocus"), ["refocus.g=2,3.5"])[0]
    assert listed.params["g"] == typed.params["g"]
    with pytest.raises(ConfigError, match="1,2"):   # as --smooth 1,2 is refused
        load_config(_config(tmp_path, "bias", "    smooth: [1, 2]\n"))
    with pytest.raises(ConfigError, match="plain value"):
        load_config(_config(tmp_path, "refocus", "    g: [[2, 3]]\n"))


def test_removing_a_parameter_reruns_the_step(project):
    text = project.read_text()
    assert re.search(r"^    smooth: \d+", text, re.M), "the demo config sets bias smooth"
    run_pipeline(load_config(project))
    project.write_text(re.sub(r"^    smooth: \d+.*\n", "", text, count=2, flags=re.M))
    decisions = {d.step.name: d for d in plan(load_config(project))}
    assert decisions["bias"].run and decisions["flat"].run
    assert re.match(r"parameter smooth changed \(\d+ -> 0\)", decisions["bias"].reason)
    assert not decisions["decode"].run


def test_outputs_record_every_resolved_parameter(project):
    run_pipeline(load_config(project))
    out = project.parent.parent / "out" / "demo" / "dualpixel"
    recorded = read_meta(out / "capture_biased.tif")["provenance"]["parameters"]
    assert set(recorded) == set(get_stages()["bias"].parameters())
    assert recorded["guard"] == 2 and recorded["crop"] is None  # defaults recorded too
    assert not [d for d in plan(load_config(project)) if d.run]


def test_dry_run_says_which_parameter_changed(project, caplog):
    run_pipeline(load_config(project))
    result = CliRunner().invoke(cli, ["run", str(project), "--dry-run", "--set", "flat.median=7"])
    assert result.exit_code == 0, result.output
    said = result.output + caplog.text  # the log goes to the handler of the first configure()
    assert re.search(r"would run\s+flat .*parameter median changed \(\d+ -> 7\)", said)


def test_every_stage_runs_with_exactly_its_declared_parameters():
    import inspect

    for stage in get_stages().values():
        run = inspect.signature(stage.run).parameters
        assert set(run) == {p.name for p in stage.params}, stage.name
        for param in stage.params:  # a direct call (a test, a script) gets the same defaults
            if run[param.name].default is not inspect.Parameter.empty:
                assert run[param.name].default == param.unset, (stage.name, param.name)


def test_simulate_params_are_checked_alike_from_the_shell_and_yaml(tmp_path):
    result = CliRunner().invoke(cli, ["simulate", "dualpixel", "-o", str(tmp_path / "s"),
                                      "--param", "noise=-5"])
    assert result.exit_code == 2  # a usage error, as any option's bad value (audit 7 E11)
    shell_message = result.output.strip().splitlines()[-1].removeprefix("Error: ")
    config = tmp_path / "c.yaml"
    config.write_text("steps:\n  simulate:\n    kind: dualpixel\n    output: s\n"
                      "    param: ['noise=-5']\n")
    with pytest.raises(ConfigError) as from_yaml:  # at load: before any step runs
        load_config(config)
    assert str(from_yaml.value).endswith(shell_message)
    assert "noise must be in [0, 65535]" in shell_message
    assert not list(tmp_path.glob("s*"))


def test_simulate_refuses_a_noise_beyond_the_sample_range(tmp_path):
    result = CliRunner().invoke(cli, ["simulate", "dualpixel", "-o", str(tmp_path / "s"),
                                      "--param", "noise=1e30"])
    assert result.exit_code == 2 and "noise must be in [0, 65535]" in result.output


@pytest.mark.parametrize("stage, extra, words", [
    ("optics", "    crosstalk: 1\n", "--crosstalk: expected true or false, got 1"),
    ("optics", "    crosstalk: [true, false]\n", "--crosstalk: expected one value"),
    ("bias", "    smooth: {a: 1}\n", "--smooth: expected a value, got a mapping"),
    ("bias", "    crop: [[2, 3]]\n", "--crop: expected a plain value"),
    ("bias", "    preview: [a.png, b.png]\n", "--preview: expected one file path"),
    ("bias", "    crop: []\n", "--crop: expected one value, got an empty list"),
], ids=["flag-number", "flag-list", "mapping", "nested", "two-paths", "empty-list"])
def test_what_no_shell_word_can_carry_is_refused(tmp_path, stage, extra, words):
    with pytest.raises(ConfigError, match=re.escape(words)):
        load_config(_config(tmp_path, stage, extra))


def test_a_yaml_flag_and_a_repeated_option_resolve_as_the_shell_gives_them(tmp_path):
    step = load_config(_config(tmp_path, "optics", "    crosstalk: true\n"))[0]
    assert step.params["crosstalk"] is True
    shell = CliRunner().invoke(cli, ["simulate", "--help"])  # --param repeats
    assert "--param KEY=VALUE" in shell.output
    config = tmp_path / "s.yaml"
    config.write_text("steps:\n  simulate:\n    kind: dualpixel\n    output: s\n"
                      "    param: noise=0\n    no-prisms: false\n")
    step = load_config(config)[0]
    assert step.params["param"] == ("noise=0",) and step.params["no_prisms"] is False


# (stage, parameter, as typed, as resolved): a value parsed from text is recorded as what it
# stands for, so the same value from the shell, YAML or --set makes one record (audit 22c M2)
TYPED_AND_RESOLVED = [
    ("refocus", "g", " 2 : 6 : 0.5 ", "2:6:0.5"),
    ("refocus", "g", " 2 , 3.0 , 4 ", "2,3,4"),
    ("refocus", "g", "4.0", "4"),
    ("refocus", "g", 4, "4"),
    ("depth", "g", " 2 : 8 ", "2:8"),
    ("depth", "g", "2.1234567:8", "2.1234567:8"),  # every digit: the stage reads this text
    ("crosstalk", "mask_widths", " 0, 1.0 ,2 ", "0,1,2"),
    ("crosstalk", "views", " A , B ", "A,B"),
    ("crosstalk", "intended", " A , B ", "A,B"),
    ("stitch", "views", "A, B,", "A,B"),
    ("simulate", "param", [" noise-x = 0 "], ("noise_x=0",)),
    ("bias", "crop", " 20 X 30 ", "20x30"),
    ("develop", "wb", " 2.1, 1 ,1.6 ", "2.1,1.0,1.6"),
]


@pytest.mark.parametrize("stage, name, typed, resolved", TYPED_AND_RESOLVED)
def test_a_value_parsed_from_text_is_kept_as_resolved(stage, name, typed, resolved):
    from plenocli.pipeline.params import convert

    param = next(p for p in get_stages()[stage].params if p.name == name)
    assert convert(param, typed) == resolved
    assert convert(param, resolved) == resolved   # resolving again changes nothing


def test_a_view_list_naming_no_view_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="names no view"):
        load_config(_config(tmp_path, "stitch", "    views: ' , '\n"))


def test_develops_output_names_are_the_formats_it_writes():
    # own-3 (round 10): develop -o x.webp was refused only when writing (exit 1), other
    # outputs' wrong suffixes are usage errors
    from plenocli.io.photo import FORMATS
    from plenocli.pipeline.schema.develop import PHOTO_SUFFIXES

    assert sorted(PHOTO_SUFFIXES) == sorted(FORMATS)
