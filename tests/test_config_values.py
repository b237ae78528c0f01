"""One reading of every value and side file: the same text means the same in the shell, a YAML
step and --set (no YAML 1.1 octal, base-60 or text exponents); a key written twice in any YAML or
JSON file is refused; a config is checked whole before any step; one file is not two inputs."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError, InputError
from plenocli.io import tiffio
from plenocli.io.yamlfile import load_yaml
from plenocli.pipeline.config import load_config
from plenocli.pipeline.registry import get_stage

ROOT = Path(__file__).resolve().parents[1]

# words as a user types them after --OPTION, or after KEY: in a config, or after --set S.K=
# (a YAML list stands for the comma-separated word)
WORDS = ["010", "+5", "-0", "1_0", "0x3", "0o7", "1e3", "3.0", "2:6", "1:30", "yes", "on",
         "1e30", ".5", "0.50", "2024-01-01", "00", "2:6:1",
         ("[2, 1, 1.50]", "2,1,1.50"), ("[02, 1, 1]", "02,1,1"),  # (YAML, the shell's word)
         ("!!float 9", "9.0"), ("!!float +3", "3.0"), ("!!int 010", "010"), ("!!str 9", "9")]
OPTIONS = [("bias", "smooth"), ("flat", "floor"), ("develop", "quality"), ("stitch", "overlap"),
           ("refocus", "g"), ("develop", "view"), ("develop", "wb")]


def _outcome(convert, value):
    try:
        return ("value", convert(value))
    except (ValueError, ConfigError) as err:
        return ("refused", type(err).__name__ == "ValueError" or "Invalid value" in str(err))


def _through_config(tmp_path: Path, stage: str, key: str, word: str, via_set: bool):
    extra = {"develop": "" if key == "view" else "    view: S\n",
             "refocus": "    grid: g.yaml\n", "flat": "    white: w.tif\n"}.get(stage, "")
    inputs = "inputs" if stage == "stitch" else "input"
    out = "out.jpg" if stage == "develop" else "out.tif"
    text = f"steps:\n  {stage}:\n    {inputs}: in.tif\n    output: {out}\n{extra}"
    path = tmp_path / "c.yaml"
    path.write_text(text if via_set else text + f"    {key}: {word}\n")
    steps = load_config(path, [f"{stage}.{key}={word}"] if via_set else [])
    return steps[0].params[key.replace("-", "_")]


@pytest.mark.parametrize("stage,key", OPTIONS)
def test_a_word_means_the_same_in_the_shell_yaml_and_set(tmp_path, stage, key):
    validator = next(p.type for p in get_stage(stage).params if p.name == key)
    for item in WORDS:
        word, shell_word = item if isinstance(item, tuple) else (item, item)
        shell = _outcome(validator.convert, shell_word)   # what click's adapter does
        for via_set in (False, True):
            got = _outcome(lambda w, s=via_set: _through_config(tmp_path, stage, key, w, s), word)
            assert got == shell, (stage, key, word, "--set" if via_set else "YAML", got, shell)


def test_yaml_scalars_are_the_shells_numbers():
    assert load_yaml("[010, 2:6, 1e30, 1:30, yes, 0x10, .inf, ~, true]") == [
        10, "2:6", 1e30, "1:30", "yes", "0x10", float("inf"), None, True]


def test_a_tagged_scalar_is_the_value_its_tag_says():
    # audit 10 E2: 'smooth: !!float 9' ran as --smooth 9 while 'smooth: 9.0' was refused; and
    # '!!bool yes' made a flag true although the plain word yes is text
    assert str(load_yaml("a: !!float 9", words=True)["a"]) == "9.0"
    with pytest.raises(ValueError, match="'yes' is not a bool"):
        load_yaml("a: !!bool yes")
    assert load_yaml("[!!bool true, !!bool FALSE]") == [True, False]


def test_a_base_60_g_refocuses_nowhere_it_was_not_asked(tmp_path):
    (tmp_path / "c.yaml").write_text("steps:\n  refocus:\n    input: in.tif\n    grid: g.yaml\n"
                                     "    output: out.tif\n    g: 2:6:1\n")
    assert load_config(tmp_path / "c.yaml")[0].params["g"] == "2:6:1"  # not 7261


# ----------------------------------------------------------------- side files with a key twice

GRID = ("lens_grid:\n  lattice: hex\n  pitch_px: 20.2\n  pitch_px: 40.4\n  angle_rad: 0.0\n"
        "  offset_xy: [5.0, 5.0]\n")
CAMERA = "focal_length_mm: 50\nfocus_distance_m: 2\nmla_sensor_mm: 0.5\nmla_sensor_mm: 5\n"


def _lens_twice() -> str:
    text = (ROOT / "configs/lenses/paper_table2.yaml").read_text()
    return text.replace("name: paper_table2\n", "name: paper_table2\nname: other\n", 1)


def _rig_twice() -> str:
    text = (ROOT / "configs/rigs/dualpixel_prism.yaml").read_text()
    first = next(line for line in text.splitlines() if line and line[0].isalpha() and ":" in line)
    return text + "\n" + first + "\n"


@pytest.mark.parametrize("name,text,read", [
    ("grid.yaml", GRID, lambda p: __import__("plenocli.io.gridfile", fromlist=["x"]).read_grid(p)),
    ("lens.yaml", _lens_twice(), lambda p: __import__(
        "plenocli.io.lensfile", fromlist=["x"]).read_lens(p)),
    ("camera.yaml", CAMERA, lambda p: __import__(
        "plenocli.pipeline.stages.depth", fromlist=["x"])._camera(str(p))),
    ("rig.yaml", _rig_twice(), lambda p: __import__(
        "plenocli.io.rigfile", fromlist=["x"]).read_rig(str(p))),
    ("t.json", '{"model": "translation", "model": "homography"}', lambda p: __import__(
        "plenocli.io.transformfile", fromlist=["x"]).read_transform(str(p), ["A", "B"])),
    ("info.json", '{"a": 1, "b": {"c": 1, "c": 2}}', lambda p: __import__(
        "plenocli.io.info", fromlist=["x"]).describe(p)),
])
def test_a_side_file_with_a_key_twice_is_refused_naming_file_and_key(tmp_path, name, text, read):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises((InputError, ConfigError)) as err:
        read(path)
    assert str(path) in str(err.value) and "given twice" in str(err.value)


SIDE_READERS = {
    "lens": lambda p: __import__("plenocli.io.lensfile", fromlist=["x"]).read_lens(p),
    "camera": lambda p: __import__("plenocli.pipeline.stages.depth", fromlist=["x"])._camera(p),
    "rig": lambda p: __import__("plenocli.io.rigfile", fromlist=["x"]).read_rig(p),
    "transform": lambda p: __import__(
        "plenocli.io.transformfile", fromlist=["x"]).read_transform(p, ["A", "B"]),
}


@pytest.mark.parametrize("kind", sorted(SIDE_READERS))
@pytest.mark.parametrize("make,words", [
    (lambda p: None, "no such file"),
    (lambda p: p.mkdir(), "is a folder"),
    (lambda p: p.symlink_to(os.devnull), "not a regular file"),  # a FIFO would block
    (lambda p: p.write_bytes(b"\xff\xfe\x00a: 1"), "not UTF-8"),
    (lambda p: p.write_text("{[: 1\n"), "line 1, column"),
])
def test_every_side_file_is_read_and_refused_the_same_way(tmp_path, kind, make, words):
    """One reading of lens, camera, rig and transform files: the same InputError, one line
    naming the file and what it is meant to be."""
    path = tmp_path / "side.file"
    make(path)
    with pytest.raises(InputError) as err:
        SIDE_READERS[kind](str(path))
    message = str(err.value)
    assert message.startswith(str(path)) and words in message and "\n" not in message


def test_a_tiff_description_with_a_key_twice_is_damaged(tmp_path):
    description = f'{{"{tiffio.FORMAT_KEY}": 1, "cfa": "RGGB", "cfa": "BGGR"}}'
    tifffile.imwrite(tmp_path / "a.tif", np.zeros((8, 8), np.float32), description=description,
                     metadata=None)
    with pytest.raises(InputError, match="given twice"):
        tiffio.read_meta(tmp_path / "a.tif")


# ------------------------------------------------------------ a config checked before any step

BASE = ("steps:\n  decode:\n    input: cap.dng\n    output: out/frames.tif\n"
        "  bias:\n    input: out/frames.tif\n    smooth: 3\n    output: out/views.tif\n")


@pytest.mark.parametrize("change,words", [
    (("out/views.tif", "out/frames.tif/v.tif"), "output file of step 'decode'"),
    (("out/views.tif", "'out/{foo}.tif'"), "unknown placeholder {foo}"),
    (("smooth: 3", "smooth: 1:30"), "'1:30' is not a valid integer"),
    (("  bias:", "  sim:\n    stage: simulate\n    kind: dualpixel\n    output: out/sim\n"
      "    no-prisms: true\n  bias:"), "does not take 'no_prisms'"),
])
@pytest.mark.parametrize("mode", [[], ["--dry-run"], ["--print-make"]])
def test_a_config_is_refused_whole_before_any_step_runs(tmp_path, monkeypatch, change, words,
                                                        mode):
    monkeypatch.chdir(tmp_path)
    Path("cap.dng").write_bytes(b"not read: the config is refused first")
    Path("c.yaml").write_text(BASE.replace(*change))
    result = CliRunner().invoke(cli, ["run", "c.yaml", *mode])
    assert result.exit_code == 1 and words in result.output, result.output
    assert not Path("out").exists()


def test_dry_run_and_print_make_together_is_a_usage_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("c.yaml").write_text(BASE)
    result = CliRunner().invoke(cli, ["run", "c.yaml", "--dry-run", "--print-make"])
    assert result.exit_code == 2 and "--dry-run" in result.output


def test_run_on_a_device_says_it_is_not_a_file():
    result = CliRunner().invoke(cli, ["run", "/dev/zero"])
    assert result.exit_code == 1 and "not a regular file" in result.output


# ------------------------------------------------------------------------- simulate parameters

@pytest.mark.parametrize("args,words", [
    (["hexgrid-white", "--param", "cfa=XYZW"], "not a 2 x 2 Bayer pattern"),
    (["quadpixel-masked", "--param", "open_quarters=00,00"], "distinct names"),
    (["lenslet-depth", "--param", "g=0.5"], "|g| must be > 1"),
    (["lenslet-depth", "--param", "g=1"], "|g| must be > 1"),
    (["raytrix-scene", "--param", "g_true=1"], "|g| must be > 1"),
    (["dualpixel", "--param", "pixels=64", "--pixels", "96"], "has its own option"),
    (["dualpixel", "--param", "noise=1", "--param", "noise=2"], "given twice"),
])
def test_simulate_refuses_what_has_no_truth_or_two_values(tmp_path, args, words):
    result = CliRunner().invoke(cli, ["simulate", *args, "-o", str(tmp_path / "s")])
    assert result.exit_code == 2 and words in result.output, result.output  # usage (E11)
    assert "internal error" not in result.output and not (tmp_path / "s").exists()


def test_simulate_reads_an_exponent_as_a_number(tmp_path):
    result = CliRunner().invoke(cli, ["simulate", "hexgrid-white", "--param", "pitch_px=1e30",
                                      "-o", str(tmp_path / "s")])
    assert result.exit_code == 2 and "pitch_px must be a number from 2" in result.output


# ------------------------------------------------------------------ one file, two input roles

def _views(path: Path) -> None:
    meta = {"views": ["S", "A", "B"], "cfa": "RGGB", "origin": [0, 0],
            "active_area": [0, 0, 16, 16], "masked_areas": []}
    tifffile.imwrite(path, np.ones((3, 16, 16), np.float32), metadata=None,
                     photometric="minisblack",
                     description=json.dumps({tiffio.FORMAT_KEY: tiffio.FORMAT_VERSION, **meta}))


@pytest.mark.parametrize("args", [
    ["flat", "in.tif", "--white", "in.tif"], ["flat", "in.tif", "--white", "./in.tif"],
    ["flat", "in.tif", "--white", "sym.tif"], ["flat", "in.tif", "--white", "hard.tif"],
    ["develop", "in.tif", "--view", "S", "--wb-from", "in.tif"],
    ["develop", "in.tif", "--view", "S", "--recover-highlights", "hard.tif"],
])
def test_one_file_in_two_input_roles_is_refused(tmp_path, monkeypatch, args):
    monkeypatch.chdir(tmp_path)
    _views(Path("in.tif"))
    os.symlink("in.tif", "sym.tif")
    os.link("in.tif", "hard.tif")
    out = "o.jpg" if args[0] == "develop" else "o.tif"
    result = CliRunner().invoke(cli, [*args, "-o", out])
    assert result.exit_code == 1 and "give each its own file" in result.output, result.output
    assert not Path(out).exists()


def test_a_frame_without_metadata_is_named_not_the_white(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _views(Path("white.tif"))
    tifffile.imwrite("in.tif", np.ones((3, 16, 16), np.float32), metadata=None,
                     photometric="minisblack",
                     description="{not json")
    result = CliRunner().invoke(cli, ["flat", "in.tif", "--white", "white.tif", "-o", "o.tif"])
    assert result.exit_code == 1 and result.output.startswith("Error: in.tif:"), result.output


def test_a_write_cut_short_by_a_file_size_limit_names_the_file(tmp_path):
    script = ("import resource, sys; resource.setrlimit(resource.RLIMIT_FSIZE, (16384, 16384));"
              "from plenocli.cli.main import cli; sys.argv = ['plenocli'] + sys.argv[1:]; cli()")
    result = subprocess.run([sys.executable, "-c", script, "simulate", "hexgrid-white",
                             "--param", "size=512", "--param", "pitch_px=20", "-o", "s"],
                            cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 1, result.stderr
    assert "could not be written whole" in result.stderr and "white.tif" in result.stderr
    assert not (tmp_path / "s").exists()


def test_every_yaml_and_json_file_is_read_by_the_one_reader():
    """A reader of its own would bring back YAML 1.1 numbers or last-wins keys."""
    import re

    pattern = re.compile(r"yaml\.(safe_)?load\(|yaml\.load_all\(|json\.loads?\((?!json\.dumps)")
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "plenocli").rglob("*.py")
                 if p.name != "yamlfile.py" and pattern.search(p.read_text())]
    assert offenders == []


def test_one_parameter_given_twice_in_a_step_or_by_set_is_refused(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("steps:\n  flat:\n    input: in.tif\n    white: w.tif\n"
                    "    save-gain: a.tif\n    save_gain: b.tif\n    output: o.tif\n")
    with pytest.raises(ConfigError, match="save-gain is given twice"):
        load_config(path)
    path.write_text(BASE)
    with pytest.raises(ConfigError, match="already set"):
        load_config(path, ["bias.smooth=5", "bias.smooth=7"])
    steps = load_config(path, ["bias.smooth=5"])  # --set replaces the config's value
    assert steps[1].params["smooth"] == 5


def test_whole_numbers_take_a_sign_everywhere_and_name_decimal_forms():
    """Audit 16 F2/M1: '+128' was taken by --seed but refused by --pixels and --crop; '1e2'
    for a whole number was refused without saying how to write it."""
    from plenocli.pipeline.validators import Int, RowsCols, SensorSize

    assert SensorSize().convert("+128") == "128" and RowsCols().convert("+64x064") == "64x64"
    assert Int(min=1).convert("+3") == 3
    for bad, words in (("1e2", "written in digits: 100"), ("10.0", "written in digits: 10"),
                       ("4_0", "not a valid integer.")):
        with pytest.raises(ValueError, match=words):
            Int().convert(bad)
    with pytest.raises(ValueError, match="ROWSxCOLS"):
        RowsCols().convert("-64x64")
