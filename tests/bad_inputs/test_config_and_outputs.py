"""The parameter path, configs, output names, and devices that fail while writing."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import tifffile
import yaml
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.io import tiffio
from plenocli.pipeline.config import load_config
from tests.bad_inputs.files import (
    assert_one_line,
    run_bad,
)

# ------------------- the parameter path and the stage edge (more in tests/cli/test_edge.py)

@pytest.mark.parametrize("step,words", [
    ({"stage": "bias", "smooth": -3}, ("smooth",)),
    ({"stage": "bias", "guard": -5}, ("guard",)),
    ({"stage": "bias", "smooth": 1.5}, ("smooth",)),
    ({"stage": "bias", "smooth": "abc"}, ("smooth",)),
])
def test_yaml_values_are_checked_like_flags(step, words, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(yaml.safe_dump({"out": str(out), "steps": {"bias": {
        **step, "input": str(inputs / "frames.tif"), "output": "{out}/b.tif"}}}))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, words)


def test_a_view_named_twice_in_yaml_is_refused_like_the_flag(inputs, tmp_path):
    # audit 9 E3: --views is checked when read, as --frames is
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(yaml.safe_dump({"out": str(out), "steps": {"stitch": {
        "inputs": [str(inputs / "biased.tif")], "views": "A, A", "output": "{out}/p.tif"}}}))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, ("--views", "'A' is named twice"))


def test_simulate_params_from_yaml_are_checked_like_flags(inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(yaml.safe_dump({"out": str(out), "steps": {"sim": {
        "stage": "simulate", "kind": "dualpixel", "output": "{out}/s",
        "param": ["noise=-5"]}}}))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, ("noise must be in [0, 65535]", "got -5"))


@pytest.mark.parametrize("args,words", [
    (["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--save-gain", "{o}/x.tif"],
     ("two outputs",)),
    (["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "--save-gain", "{i}/biased.tif"],
     ("also an input",)),
])
def test_outputs_that_collide_are_refused(args, words, inputs, tmp_path):
    result = run_bad(inputs, tmp_path / "out", [*args, "-o", "{o}/x.tif"])
    assert_one_line(result, 1, words)


@pytest.mark.parametrize("args", [
    ["decode", "{i}/dp.dng", "-o", "{o}/x.tif", "--preview", "{o}/x.jpg"],
    ["decode", "{i}/dp.dng", "-o", "{o}/x.tif", "--preview", "{o}/x"],
    ["decode", "{i}/dp.dng", "-o", "{o}/x.png"],
    ["flat", "{i}/biased.tif", "--white", "{i}/biased.tif", "-o", "{o}/x.tif", "--save-gain",
     "{o}/g.png"],
    ["develop", "{i}/biased.tif", "--view", "S", "-o", "{o}/x.jpg", "--linear", "{o}/l.png"],
    ["optics", "{i}/none.yaml", "--json", "{o}/x.yaml"],
])
def test_an_output_named_for_another_format_is_refused(args, inputs, tmp_path):
    result = run_bad(inputs, tmp_path / "out", args)
    assert_one_line(result, 2, ("ending in",))


@pytest.mark.parametrize("args,words", [
    (["decode", "{i}/dp.dng", "-o", "{o}/.tif"], "has no name before its suffix"),
    (["decode", "{i}/dp.dng", "-o", "{o}/x.tif", "--preview", "{o}/.PNG"],
     "has no name before its suffix"),
    (["decode", "{i}/dp.dng", "-o", "{o}/nl\nname.tif"], "holds a control character ('\\n')"),
    (["simulate", "dualpixel", "-o", "{o}/a\tb"], "holds a control character ('\\t')"),
])
def test_an_output_name_that_is_only_a_suffix_or_holds_a_newline_is_refused(args, words, inputs,
                                                                              tmp_path):
    # audit 7 E14: '-o .tif' was told to end in .tif; a newline split the one-line messages
    result = run_bad(inputs, tmp_path / "out", args)
    assert_one_line(result, 2, (words,))


def _config_text(inputs: Path, out: Path, extra_bias: str = "", extra_steps: str = "",
                 top: str = "") -> str:
    return (f"out: {out}\n{top}steps:\n"
            f"  decode:\n    input: {inputs}/dp.dng\n    output: \"{{out}}/f.tif\"\n"
            f"  bias:\n    input: \"{{out}}/f.tif\"\n    output: \"{{out}}/b.tif\"\n{extra_bias}"
            f"{extra_steps}")


@pytest.mark.parametrize("name,parts,words", [
    ("duplicate-parameter", {"extra_bias": "    smooth: 1\n    smooth: 2\n"}, ("twice",)),
    ("duplicate-step", {"extra_steps": "  decode:\n    input: x.dng\n    output: y.tif\n"},
     ("twice",)),
    ("step-scalar", {"extra_steps": "  sai: 5\n"}, ("mapping",)),
    ("stage-list", {"extra_steps": "  x:\n    stage: [bias]\n"}, ("stage",)),
    ("two-writers", {"extra_steps": "  decode2:\n    stage: decode\n    input: x.dng\n"
                                     "    output: \"{out}/f.tif\"\n"}, ("both write",)),
    ("own-input", {"extra_steps": "  bias2:\n    stage: bias\n    input: \"{out}/b2.tif\"\n"
                                   "    output: \"{out}/b2.tif\"\n"}, ("also an input",)),
    ("preview-not-png", {"extra_bias": "    preview: \"{out}/b.jpg\"\n"}, ("ending in .png",)),
    # audit 8 W4: a YAML set was taken as its Python repr, in hash order ("{'A'", "'S'}")
    ("frames-set", {"extra_steps": "  decode2:\n    stage: decode\n    input: x.dng\n"
                                    "    output: \"{out}/g.tif\"\n    frames: !!set {S, A}\n"},
     ("plain value",)),
    ("frames-twice", {"extra_steps": "  decode2:\n    stage: decode\n    input: x.dng\n"
                                      "    output: \"{out}/g.tif\"\n    frames: S,S\n"},
     ("given twice",)),
])
def test_config_structure_is_checked_before_any_step_runs(name, parts, words, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out, **parts))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, words)


@pytest.mark.parametrize("value, words", [
    ("5", "'out:'"), ("[a, b]", "'out:'"), ("{a: 1}", "'out:'"),
    # audit 7 E15: out: "{out}" wrote into a folder literally named {out}
    ('"{out}"', "holds a placeholder"), ('"runs/{name}"', "holds a placeholder"),
    ('"{foo}/x"', "holds a placeholder")])
def test_config_out_must_be_one_folder_without_placeholders(value, words, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out).replace(f"out: {out}", f"out: {value}"))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, (words,))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "pipeline.yaml"]


def test_a_short_write_on_a_full_device_says_no_space(tmp_path, monkeypatch):
    import errno
    from types import SimpleNamespace

    from plenocli.io import atomic

    monkeypatch.setattr(atomic.os, "statvfs", lambda p: SimpleNamespace(f_bavail=0,
                                                                        f_frsize=4096))
    with pytest.raises(OSError) as info, atomic.atomic_path(tmp_path / "x.tif") as tmp:
        tmp.write_bytes(b"half")
        raise OSError("6144 requested and 2992 written")  # numpy's short write: no errno
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / "x.tif")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["x.json", ".x.tif.plenocli.json", "p.png"])
def test_a_full_device_while_a_record_or_preview_is_written_names_it(tmp_path, name):
    # audit 7 E16: a write without a file name (a record, a preview) said "no space left"
    # without naming the file
    import errno

    from plenocli.errors import os_error_message
    from plenocli.io import atomic

    with pytest.raises(OSError) as info, atomic.atomic_path(tmp_path / name) as tmp:
        tmp.write_bytes(b"half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(tmp_path / name)
    assert os_error_message(info.value).startswith(f"{tmp_path / name}: no space left")
    assert list(tmp_path.iterdir()) == []


def test_a_missing_codec_is_named_not_taken_for_damage(tmp_path):
    err = KeyError("<COMPRESSION.LZW: 5> requires the 'imagecodecs' package")
    message = str(tiffio.read_error(tmp_path / "x.tif", err, "fallback"))
    assert "compressed with LZW" in message and "imagecodecs" in message
    assert str(tiffio.read_error(tmp_path / "x.tif", ValueError("bad"), "fallback")) == "fallback"


def test_a_bigtiff_sensor_image_decodes(tmp_path):
    sensor = np.arange(64 * 96, dtype=np.uint16).reshape(64, 96)
    tifffile.imwrite(tmp_path / "big.tif", sensor, bigtiff=True)
    result = CliRunner().invoke(cli, ["decode", str(tmp_path / "big.tif"), "-o",
                                      str(tmp_path / "frames.tif")])
    assert result.exit_code == 0, result.output
    frames, _ = tiffio.read_image(tmp_path / "frames.tif")
    assert np.array_equal(frames[0], sensor)


def test_set_reaches_a_step_whose_name_has_a_dot(inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    text = _config_text(inputs, out).replace("  bias:\n", "  bias.v2:\n    stage: bias\n")
    config.write_text(text)
    result = run_bad(inputs, out, ["run", str(config), "--dry-run", "--set", "bias.v2.smooth=-3"])
    assert_one_line(result, 2, ("step 'bias.v2'", "--smooth"))  # the value alone: a usage error


@pytest.mark.parametrize("word, code, words", [
    # audit 9 E5: ' 2 : 8 ' read as the YAML mapping {2: 8}: "expected a value, got a mapping"
    (" 2 : 4 ", 0, ()),
    ("a: b", 2, ("--set 'depth.g=a: b': step 'depth'", "got 'a: b'")),
    ("abc", 2, ("--set 'depth.g=abc': step 'depth'", "Invalid value for '--g'")),
    ("[2", 2, ("--set 'depth.g=[2'", "not valid YAML")),
    # audit 18 W1: YAML read ' # c' as a comment and ran with 2:4 (another file, for a path)
    ("2:4 # c", 2, ("--set 'depth.g=2:4 # c'", "'# c' as a comment", "quote the value")),
    ("#2:4", 2, ("'#2:4' as a comment",)),
    # audit 21 M3: quoted already, it was told to quote it again (--set 'depth.g=""2:4" # c"')
    ('"2:4" # c', 2, ("after the quoted value", "leave it out (--set 'depth.g=\"2:4\"')")),
])
def test_a_set_value_is_the_word_and_its_refusal_a_usage_error(word, code, words, inputs,
                                                                tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  depth:\n    input: {inputs}/rt/frames.tif\n"
                      f"    grid: {inputs}/rt/grid.yaml\n    output: {out}/d.tif\n")
    result = run_bad(inputs, out, ["run", str(config), "--dry-run", "--set", f"depth.g={word}"])
    if code == 0:
        assert result.exit_code == 0, result.output
        step = load_config(config, [f"depth.g={word}"])[0]
        assert step.params["g"].replace(" ", "") == "2:4"
    else:
        assert_one_line(result, code, words)


@pytest.mark.parametrize("param", ["s", "min-confidence"])
def test_a_placeholder_in_a_number_is_a_usage_error_of_the_set(param, inputs, tmp_path):
    """Audit 21 M3: filled per capture, it failed each capture naming the config (exit 1)."""
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  depth:\n    input: {inputs}/rt/frames.tif\n"
                      f"    grid: {inputs}/rt/grid.yaml\n    output: {tmp_path}/d.tif\n")
    result = run_bad(inputs, tmp_path / "out", ["run", str(config), "--dry-run", "--set",
                                                f"depth.{param}={{{{name}}}}"])  # run_bad formats
    assert_one_line(result, 2, (f"--set 'depth.{param}={{name}}'", "takes a number"))


# ---- issue 21, class 8: unreadable inputs, lists for one path, empty values, cycles, long names

def _deny_reading(monkeypatch, path: Path) -> None:
    """Make ``path`` unreadable, even for root (who ignores permission bits): os.access says so
    and opening it fails with EACCES, as for a file of another user."""
    import builtins
    import errno
    import io
    import os

    target = os.path.realpath(path)
    real_access, real_open = os.access, builtins.open

    def access(p, mode, *args, **kwargs):
        if os.path.realpath(p) == target and mode & os.R_OK:
            return False
        return real_access(p, mode, *args, **kwargs)

    def opener(file, *args, **kwargs):
        if isinstance(file, (str, bytes, os.PathLike)) and os.path.realpath(file) == target:
            raise PermissionError(errno.EACCES, "Permission denied", str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(builtins, "open", opener)
    monkeypatch.setattr(io, "open", opener)


@pytest.mark.parametrize("args", [
    ["bias", "{f}", "-o", "{o}/b.tif"],
    ["flat", "{i}/biased.tif", "--white", "{f}", "-o", "{o}/v.tif"],
    ["info", "{f}"],
    ["run", "{c}"],
], ids=["argument", "option", "info", "run-config"])
def test_an_unreadable_input_is_an_input_error_not_a_usage_error(args, inputs, tmp_path,
                                                                 monkeypatch):
    secret = tmp_path / "secret.tif"
    secret.write_bytes((inputs / "biased.tif").read_bytes())
    config = tmp_path / "secret.tif"  # run reads it as its config
    out = tmp_path / "out"
    out.mkdir()
    _deny_reading(monkeypatch, secret)
    argv = [a.format(i=inputs, o=out, f=secret, c=config) for a in args]
    result = CliRunner().invoke(cli, argv)
    assert_one_line(result, 1, ("secret.tif", "ermission denied"))
    assert not list(out.iterdir())


def test_every_input_path_is_left_to_its_reader_to_check(tmp_path, monkeypatch):
    from plenocli.pipeline.registry import get_stages
    from plenocli.pipeline.validators import InputFile

    secret = tmp_path / "secret.tif"
    secret.write_bytes(b"")
    _deny_reading(monkeypatch, secret)
    for stage in get_stages().values():
        for param in stage.params:
            if param.role == "input":
                assert isinstance(param.type, InputFile), f"{stage.name} {param.name}"
                assert param.type.convert(str(secret)) == str(secret)  # the reader says why


@pytest.mark.parametrize("value", ["[a.tif, b.tif]", "[]"])
def test_a_list_for_one_output_path_is_refused(value, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out).replace('output: "{out}/b.tif"',
                                                        f"output: {value}"))
    result = run_bad(inputs, out, ["run", str(config)])
    assert_one_line(result, 1, ("--output", "one file path"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "pipeline.yaml"]


@pytest.mark.parametrize("how,words", [
    (["--set", "bias.smooth="], ("--smooth", "''")),
    (["--set", "bias.smooth=~"], ("smooth", "no value")),
    (["--set", "bias.smooth=null"], ("smooth", "no value")),
    (["--set", "bias.input="], ("INPUT", "empty")),
    ("smooth: null", ("smooth", "no value")),
    ("smooth:", ("smooth", "no value")),
], ids=["set-empty", "set-tilde", "set-null", "set-empty-path", "yaml-null", "yaml-empty"])
def test_an_empty_or_null_value_is_refused_not_taken_for_the_default(how, words, inputs,
                                                                     tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    extra = f"    {how}\n" if isinstance(how, str) else "    smooth: 3\n"
    config.write_text(_config_text(inputs, out, extra_bias=extra))
    flags = how if isinstance(how, list) else []
    for mode in (["--dry-run"], ["--print-make"], []):
        result = run_bad(inputs, out, ["run", str(config), *flags, *mode])
        assert_one_line(result, 2 if flags else 1, words)  # a --set value: a usage error


@pytest.mark.parametrize("steps", [
    "  a:\n    stage: bias\n    input: \"{out}/y.tif\"\n    output: \"{out}/x.tif\"\n"
    "  b:\n    stage: bias\n    input: \"{out}/x.tif\"\n    output: \"{out}/y.tif\"\n",
    "  a:\n    stage: bias\n    input: \"{out}/b.tif\"\n    output: \"{out}/x.tif\"\n",
], ids=["cycle", "out-of-order"])
def test_print_make_refuses_what_run_refuses(steps, inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    text = _config_text(inputs, out).replace("steps:\n", "steps:\n" + steps)
    config.write_text(text)
    for mode in ([], ["--print-make"], ["--dry-run"]):
        result = run_bad(inputs, out, ["run", str(config), *mode])
        assert_one_line(result, 1, ("writes after it",))
        assert not result.stdout


@pytest.mark.parametrize("steps, words", [
    ("  depth:\n    input: \"{out}/b.tif\"\n    output: \"{out}/d.tif\"\n"
     "  develop:\n    input: \"{out}/d.tif\"\n    wb: 1,1,1\n    matrix: none\n"
     "    output: \"{out}/p.jpg\"\n", ("step 'develop'", "`plenocli depth` output")),
    ("  bias2:\n    stage: bias\n    input: \"{out}/b.tif\"\n    output: \"{out}/b2.tif\"\n",
     ("step 'bias2'", "`plenocli bias` output; bias takes as input the output of decode")),
    ("  flat:\n    input: \"{out}/b.tif\"\n    white: {i}/biased.tif\n"
     "    save-gain: \"{out}/g.tif\"\n    output: \"{out}/fl.tif\"\n"
     "  stitch:\n    inputs: \"{out}/g.tif\"\n    output: \"{out}/p.tif\"\n",
     ("step 'stitch'", "`plenocli flat --save-gain` output (a gain map")),
    ("  develop:\n    input: \"{out}/b.tif\"\n    view: S\n    wb: 1,1,1\n    matrix: none\n"
     "    output: \"{out}/p.tif\"\n  develop2:\n    stage: develop\n"
     "    input: \"{out}/p.tif\"\n    output: \"{out}/p2.jpg\"\n",
     ("step 'develop2'", "`plenocli develop` photograph", "/b.tif)")),
    ("  simulate:\n    kind: dualpixel\n    output: \"{out}/sim\"\n"
     "  decode2:\n    stage: decode\n    input: \"{out}/sim/truth.json\"\n"
     "    output: \"{out}/t.tif\"\n", ("step 'decode2'", "ground truth `plenocli simulate`",
                                       "not a raw")),
    ("  simulate:\n    kind: dualpixel\n    output: \"{out}/sim\"\n"
     "  bias2:\n    stage: bias\n    input: \"{out}/sim/capture.dng\"\n"
     "    output: \"{out}/b2.tif\"\n", ("step 'bias2'", "raw capture", "decode it first")),
    # audit 13 E2: the roles beside the main input were not checked (run ran every earlier step)
    ("  flat:\n    input: \"{out}/b.tif\"\n    white: {i}/biased.tif\n"
     "    output: \"{out}/fl.tif\"\n  flat2:\n    stage: flat\n    input: \"{out}/b.tif\"\n"
     "    gain: \"{out}/fl.tif\"\n    output: \"{out}/x.tif\"\n",
     ("step 'flat2'", "`plenocli flat` output; flat takes as gain the gain map")),
    ("  flat:\n    input: \"{out}/b.tif\"\n    white: {i}/biased.tif\n"
     "    save-gain: \"{out}/g.tif\"\n    output: \"{out}/fl.tif\"\n"
     "  stitch:\n    inputs: \"{out}/fl.tif\"\n    views: A,B\n    transform-in: \"{out}/g.tif\"\n"
     "    output: \"{out}/p.tif\"\n",
     ("step 'stitch'", "`plenocli flat --save-gain` output", "takes as transform-in")),
    # audit 17 M1: a transform given as the rig is told where it goes
    ("  stitch:\n    inputs: \"{out}/b.tif\"\n    views: A,B\n    transform-out: \"{out}/t.json\"\n"
     "    output: \"{out}/p.tif\"\n  stitch2:\n    stage: stitch\n    inputs: \"{out}/b.tif\"\n"
     "    views: A,B\n    rig: \"{out}/t.json\"\n    output: \"{out}/p2.tif\"\n",
     ("step 'stitch2'", "`plenocli stitch --transform-out` output",
      "a --transform-out goes to --transform-in")),
    # audit 16 M3: crosstalk's report as mixing was not told what unmix takes
    ("  crosstalk:\n    inputs: \"{out}/b.tif\"\n    output: \"{out}/x.json\"\n"
     "  unmix:\n    inputs: \"{out}/b.tif\"\n    mixing: \"{out}/x.json\"\n"
     "    output: \"{out}/u.tif\"\n", ("step 'unmix'", "not an image unmix can take as mixing",
                                       "unmix takes as mixing the output of crosstalk "
                                       "--mixing-out")),
    ("  depth:\n    input: \"{out}/b.tif\"\n    output: \"{out}/d.tif\"\n"
     "  refocus:\n    input: \"{out}/f.tif\"\n    grid: \"{out}/d.tif\"\n"
     "    output: \"{out}/r.tif\"\n", ("step 'refocus'", "`plenocli depth` output",
                                         "takes as grid a lens grid")),
    # audit 14 E1: simulate's documents in a side role passed (run ran every earlier step)
    *[("  simulate:\n    kind: dualpixel\n    output: \"{out}/sim\"\n"
       f"  last:\n    {step}: \"{{out}}/sim/{name}\"\n    output: \"{{out}}/x.{suffix}\"\n",
       ("step 'last'", f"`plenocli simulate` writes ({name})", f"takes as {role}"))
      for step, name, suffix, role in (
          ("stage: calibrate\n    input: \"{out}/b.tif\"\n    start", "truth.json", "yaml",
           "start"),
          ("stage: stitch\n    inputs: \"{out}/b.tif\"\n    views: A,B\n    transform-in",
           "truth.json", "tif", "transform-in"),
          ("stage: depth\n    input: {i}/rt/frames.tif\n    grid: {i}/rt/grid.yaml\n    camera",
           "truth.json", "tif", "camera"),
          ("stage: flat\n    input: \"{out}/b.tif\"\n    gain", "truth.npz", "tif", "gain"))],
    *[("  develop:\n    input: \"{out}/b.tif\"\n    view: S\n    wb: 1,1,1\n    matrix: none\n"
       "    output: \"{out}/p.jpg\"\n    linear: \"{out}/l.tif\"\n  develop2:\n"
       f"    stage: develop\n    input: \"{{out}}/l.tif\"\n    {role}: {{i}}/biased.tif\n"
       "    output: \"{out}/p2.jpg\"\n", ("step 'develop2'", f"--{role} ", words))
      for role, words in (("wb-from", "white-balanced already"),
                          ("recover-highlights", "no dual-pixel A, B, S views"))],
], ids=["develop-of-depth", "bias-twice", "gain-as-views", "photograph-to-develop",
        "decode-of-truth-json", "bias-of-simulated-raw", "gain-of-flat-output",
        "transform-in-of-gain", "transform-in-of-report", "mixing-of-report", "grid-of-depth-map",
        "start-of-truth", "transform-in-of-truth", "camera-of-truth", "gain-of-truth-arrays",
        "linear-with-wb-from", "linear-with-recover-highlights"])
def test_a_step_fed_an_output_its_stage_refuses_is_refused_before_any_step_runs(
        steps, words, inputs, tmp_path):
    """audit 12 E4: the producing step's stage is known before anything runs, yet --dry-run
    said "would run" and run ran every earlier step before the stage refused the file."""
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out, extra_steps=steps.replace("{i}", str(inputs))))
    for mode in ([], ["--print-make"], ["--dry-run"]):
        result = run_bad(inputs, out, ["run", str(config), *mode])
        assert_one_line(result, 1, words)
        assert not result.stdout


def test_side_files_wired_to_the_step_that_makes_them_would_run(inputs, tmp_path):
    """The side roles are checked against what an earlier step writes, and the wirings that
    make them (save-gain -> gain, transform-out -> transform-in, linear -> develop) pass."""
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out, extra_steps=(
        f"  flat:\n    input: \"{{out}}/b.tif\"\n    white: {inputs}/biased.tif\n"
        "    save-gain: \"{out}/g.tif\"\n    output: \"{out}/fl.tif\"\n"
        "  flat2:\n    stage: flat\n    input: \"{out}/b.tif\"\n    gain: \"{out}/g.tif\"\n"
        "    output: \"{out}/fl2.tif\"\n"
        "  stitch:\n    inputs: \"{out}/fl.tif\"\n    views: A,B\n"
        "    transform-out: \"{out}/t.json\"\n    output: \"{out}/p.tif\"\n"
        "  stitch2:\n    stage: stitch\n    inputs: \"{out}/fl2.tif\"\n    views: A,B\n"
        "    transform-in: \"{out}/t.json\"\n    output: \"{out}/p2.tif\"\n"
        # audit 17 F1: a stitch report holds its transform and the rig it used, as the
        # command takes it
        "  stitch3:\n    stage: stitch\n    inputs: \"{out}/fl.tif\"\n    views: A,B\n"
        "    report: \"{out}/r.json\"\n    output: \"{out}/p3.tif\"\n"
        "  stitch4:\n    stage: stitch\n    inputs: \"{out}/fl2.tif\"\n    views: A,B\n"
        "    rig: \"{out}/r.json\"\n    output: \"{out}/p4.tif\"\n"
        "  stitch5:\n    stage: stitch\n    inputs: \"{out}/fl2.tif\"\n    views: A,B\n"
        "    transform-in: \"{out}/r.json\"\n    output: \"{out}/p5.tif\"\n"
        "  develop:\n    input: \"{out}/fl.tif\"\n    view: S\n    wb: 1,1,1\n"
        "    matrix: none\n    output: \"{out}/p.jpg\"\n    linear: \"{out}/l.tif\"\n"
        "  develop2:\n    stage: develop\n    input: \"{out}/l.tif\"\n    wb: 1,1.1,1\n"
        "    output: \"{out}/p2.jpg\"\n")))
    for mode in ("--print-make", "--dry-run"):
        result = CliRunner().invoke(cli, ["run", str(config), mode])
        assert result.exit_code == 0, result.output
    assert not out.exists()


def test_simulated_grids_wired_as_grids_would_run_and_its_truth_is_refused_from_the_shell(
        inputs, tmp_path):
    """audit 14 E1: simulate's documents are judged by kind, its true grids (grid.yaml,
    grid_true.xml) still go where a grid goes; a truth.json already written is named in a side
    role from the shell too (it was "the transform's view_to_reference is NoneType")."""
    config = tmp_path / "c.yaml"
    steps = {"hw": {"stage": "simulate", "kind": "hexgrid-white", "output": "hw"},
             "ld": {"stage": "simulate", "kind": "lenslet-depth", "output": "ld"},
             "decode": {"input": "hw/white.tif", "calib": "hw/grid_true.xml", "camera": "raytrix",
                        "output": "wf.tif"},
             "calibrate": {"input": "wf.tif", "start": "hw/grid_true.xml",
                           "compare": "ld/grid.yaml", "output": "g.yaml"},
             "refocus": {"input": "ld/frames.tif", "grid": "ld/grid.yaml", "s": 0.2, "g": 4,
                         "output": "r.tif"}}
    config.write_text(yaml.safe_dump({"steps": steps}, sort_keys=False))
    for mode in ("--dry-run", "--print-make"):
        result = CliRunner().invoke(cli, ["run", str(config), mode])
        assert result.exit_code == 0, result.output
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"kind": "stereo-rig", "provenance": {"stage": "simulate"}}))
    result = CliRunner().invoke(cli, ["stitch", str(inputs / "biased.tif"), "--views", "A,B",
                                      "--transform-in", str(truth), "-o",
                                      str(tmp_path / "p.tif")])
    assert_one_line(result, 1, ("ground truth `plenocli simulate` writes",
                                "takes as transform-in"))


def test_a_plain_sensor_tiff_a_simulate_step_writes_is_decoded(tmp_path):
    """review 12 item 1: every TIFF in a simulate step's folder was planned as a plenocli
    output, so decode of raytrix-ghost's plain white.tif (decode's from the shell) was refused
    by --dry-run and run (configs/raytrix_r5.yaml with its fixtures step in front). Which kind
    of TIFF a kind writes is known when it runs: its stage checks it then; decode's frames start
    a history known before (bias of bias output is still refused before any step runs)."""
    config = tmp_path / "c.yaml"
    steps = {"sim": {"stage": "simulate", "kind": "raytrix-ghost", "pixels": 96,
                     "output": "sd/rg"},
             "decode": {"input": "sd/rg/white.tif", "output": "sd/wf.tif"},
             "bias": {"input": "sd/wf.tif", "output": "sd/wb.tif"}}
    config.write_text(yaml.safe_dump({"steps": steps}, sort_keys=False))
    for mode in (["--dry-run"], []):
        result = CliRunner().invoke(cli, ["run", str(config), *mode])
        assert result.exit_code == 0, result.output
    assert (tmp_path / "sd" / "wb.tif").is_file()
    steps["bias2"] = {"stage": "bias", "input": "sd/wb.tif", "output": "sd/wb2.tif"}
    steps["sim"]["output"], steps["decode"]["input"] = "s2/rg", "s2/rg/white.tif"
    config.write_text(yaml.safe_dump({"steps": steps}, sort_keys=False))
    result = CliRunner().invoke(cli, ["run", str(config)])
    assert_one_line(result, 1, ("step 'bias2'", "`plenocli bias` output"))
    assert not (tmp_path / "s2").exists()


def test_print_make_refuses_an_input_that_nothing_makes(inputs, tmp_path):
    out = tmp_path / "out"
    config = tmp_path / "pipeline.yaml"
    config.write_text(_config_text(inputs, out).replace(f"{inputs}/dp.dng", "nowhere.dng"))
    for mode in ([], ["--print-make"]):
        result = run_bad(inputs, out, ["run", str(config), *mode])
        assert_one_line(result, 1, ("nowhere.dng does not exist",))


def test_an_output_name_of_255_bytes_is_written_with_its_record(inputs, tmp_path):
    from plenocli.pipeline.records import read_record, record_path
    from plenocli.pipeline.runner import plan

    name = "b" * 251 + ".tif"
    result = CliRunner().invoke(cli, ["bias", str(inputs / "frames.tif"), "-o",
                                      str(tmp_path / name), "-q"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / name).is_file() and read_record(tmp_path / name) is not None
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([name,
                                                                 record_path(name).name])
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  bias:\n    input: {inputs / 'frames.tif'}\n"
                      f"    output: {name}\n")
    assert [d.run for d in plan(load_config(config))] == [False]
    too_long = CliRunner().invoke(cli, ["bias", str(inputs / "frames.tif"), "-o",
                                        str(tmp_path / ("c" * 252 + ".tif"))])
    assert_one_line(too_long, 1, ("too long",))


def test_a_name_too_long_is_refused_alike_by_run_dry_run_print_make_and_batch(inputs, tmp_path):
    """Audit 21 I1/M2: run refused a step output whose name the file system cannot take, but
    --dry-run and --print-make passed it (exit 0) and batch failed the capture as 'internal
    error: OSError: File name too long' (its up-to-date check looked the name up)."""
    out = tmp_path / "out"
    config = tmp_path / "c.yaml"
    config.write_text(f"steps:\n  bias:\n    input: {inputs / 'frames.tif'}\n"
                      f"    output: {out / ('n' * 252 + '.tif')}\n")
    for mode in ([], ["--dry-run"], ["--print-make"]):
        result = run_bad(inputs, out, ["run", str(config), *mode])
        assert_one_line(result, 1, ("shorten it",))
    template = tmp_path / "b.yaml"
    template.write_text('steps:\n  bias: {input: "{capture}", output: "{out}/{name}/b.tif"}\n')
    for mode in (["--dry-run"], ["-j", "1"]):
        result = CliRunner().invoke(cli, ["batch", str(template), "--inputs",
                                          str(inputs / "frames.tif"), "--out",
                                          str(tmp_path / ("x" * 256)), *mode])
        assert result.exit_code == 1, result.output
        assert "shorten it" in result.output
        assert "internal error" not in result.output


def test_a_check_that_reads_an_input_an_earlier_step_makes_holds_on_the_first_run(tmp_path):
    """develop --method on colour pages is refused from what INPUT holds. Loaded before the
    run, the check could not see a file that an earlier step makes: the first run developed
    with a method that did nothing (exit 0), the next run of the same config refused it. Each
    step's checks are made again just before it runs."""
    import cv2

    rng = np.random.default_rng(0)
    cv2.imwrite(str(tmp_path / "rgb.png"), rng.integers(0, 255, (24, 32, 3), np.uint8))
    out = tmp_path / "out"
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"steps": {
        "decode": {"input": str(tmp_path / "rgb.png"), "output": str(out / "f.tif")},
        "develop": {"input": str(out / "f.tif"), "wb": "1,1,1", "matrix": "none",
                    "method": "bilinear", "output": str(out / "p.jpg")}}}))
    for _ in range(2):
        result = CliRunner().invoke(cli, ["run", str(config)])
        assert result.exit_code == 1 and "--method" in result.output, result.output
        assert not (out / "p.jpg").exists()
