"""Audit 19a I1, I2, U1, M1 (YAML part), E1, E2: YAML aliases, a description that is not text,
tagged values for paths, outputs that are not regular files, records that are links."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from plenocli.cli.main import cli
from plenocli.io.yamlfile import DocumentError, load_yaml
from tests.bad_inputs.files import assert_one_line


def _bomb(levels: int) -> str:
    """A list of 10**levels values in a few hundred bytes (aliases to aliases)."""
    items = ["&a0 [x, x, x, x, x, x, x, x, x, x]"] + [
        f"&a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, levels + 1)]
    return "[" + ", ".join(items) + "]"


def _config(folder: Path, frames: str = "S", top: str = "") -> Path:
    Image.fromarray(np.arange(48, dtype=np.uint8).reshape(6, 8)).save(folder / "in.png")
    config = folder / "c.yaml"
    config.write_text(f"{top}steps:\n  decode: {{input: in.png, output: out/f.tif, "
                      f"frames: {frames}}}\n")
    return config


@pytest.mark.parametrize("text", ["&a [*a]", "a: &s {b: *s}", "[&x 1, *x]", _bomb(8),
                                  "<<: *base"])
def test_every_alias_is_refused_before_anything_is_built(text):
    # audit 19a I2/U1: '&a [*a]' was a RecursionError ("internal error"); the 8-level bomb
    # (10^8 values in 500 bytes) ran for hours in run, --dry-run and info
    start = time.perf_counter()
    with pytest.raises(DocumentError, match=r"an alias \(\*\w+\)"):
        load_yaml(text, words=True)
    assert time.perf_counter() - start < 1.0
    assert load_yaml("a: &x 5\nb: '*x'\nc: x*y  # *z\n") == {"a": 5, "b": "*x", "c": "x*y"}


@pytest.mark.parametrize("args, code", [
    (["run", "{c}", "--dry-run"], 1), (["info", "{c}"], 1),
    (["run", "{c0}", "--dry-run", "--set", "decode.frames=&a [*a]"], 2),
    (["simulate", "dualpixel", "-o", "{d}/sx", "--pixels", "32", "--param", "noise=&a [*a]"], 2),
])
def test_an_alias_is_one_line_in_every_command(args, code, tmp_path):
    config0 = _config(tmp_path)
    config = tmp_path / "r.yaml"
    config.write_text(config0.read_text().replace("frames: S", "frames: &a [*a]"))
    argv = [a.format(c=config, c0=config0, d=tmp_path) for a in args]
    result = CliRunner().invoke(cli, argv)
    assert_one_line(result, code, ("alias (*a)",))
    assert "Recursion" not in result.output + result.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "sx").exists()


@pytest.mark.parametrize("value", ["5", "[a, b]", "{a: 1}"])
def test_a_description_that_is_not_text_is_refused_by_run_and_info_alike(value, tmp_path):
    # audit 19a I1: info said "internal error: AttributeError", run took the config
    config = _config(tmp_path, top=f"description: {value}\n")
    result = CliRunner().invoke(cli, ["run", str(config), "--dry-run"])
    assert_one_line(result, 1, ("'description:' must be text",))
    info = CliRunner().invoke(cli, ["info", str(config)])
    assert info.exit_code == 0, info.output
    assert "run refuses it:" in info.output and "'description:' must be text" in info.output


@pytest.mark.parametrize("value, said", [
    ("!!binary YQ==", "binary data (!!binary, 1 byte)"), ("!!set {in.png}", "a set (!!set)"),
    ("!!omap [a: 1]", "!!omap"), ("!!timestamp 2001-01-01", "a date")])
@pytest.mark.parametrize("how", ["yaml", "set"])
def test_a_path_given_a_tagged_value_is_refused_as_any_key_is(value, said, how, tmp_path):
    # audit 19a M1: 'input: !!binary YQ==' decoded the file named "b'a'" (exit 0)
    config = _config(tmp_path)
    args = ["run", str(config)]
    if how == "yaml":
        config.write_text(config.read_text().replace("input: in.png", f"input: {value}"))
    else:
        args += ["--set", f"decode.input={value}"]
    result = CliRunner().invoke(cli, args)
    assert_one_line(result, 1 if how == "yaml" else 2, ("expected a plain value", said))
    assert "b'" not in result.output + result.stderr and not (tmp_path / "out").exists()


def _png(folder: Path) -> Path:
    Image.fromarray(np.arange(48, dtype=np.uint8).reshape(6, 8)).save(folder / "in.png")
    return folder / "in.png"


@pytest.mark.parametrize("link", [False, True])
def test_an_output_that_is_a_pipe_is_refused_not_replaced(link, tmp_path):
    # audit 19a E1: a FIFO (or a link to one, or to a device) was replaced by a regular file
    src = _png(tmp_path)
    os.mkfifo(tmp_path / "p.tif")
    out = tmp_path / "p.tif"
    if link:
        (tmp_path / "l.tif").symlink_to("p.tif")
        out = tmp_path / "l.tif"
    result = CliRunner().invoke(cli, ["decode", str(src), "-o", str(out)])
    assert_one_line(result, 1, ("not a regular file (a device, pipe or socket)",))
    assert (tmp_path / "p.tif").is_fifo()
    assert not list(tmp_path.glob(".*"))


def test_a_record_that_is_a_link_is_replaced_never_written_through(tmp_path):
    # audit 19a E2: '.r.tif.plenocli.json -> in.png' replaced the input by the record; a link
    # to another file overwrote that file
    src = _png(tmp_path)
    before = src.read_bytes()
    (tmp_path / ".r.tif.plenocli.json").symlink_to("in.png")
    result = CliRunner().invoke(cli, ["decode", str(src), "-o", str(tmp_path / "r.tif")])
    assert_one_line(result, 1, ("is a link to in.png", "remove the link"))
    assert src.read_bytes() == before and not (tmp_path / "r.tif").exists()

    (tmp_path / "victim.txt").write_text("keep")
    (tmp_path / ".s.tif.plenocli.json").symlink_to("victim.txt")
    result = CliRunner().invoke(cli, ["decode", str(src), "-o", str(tmp_path / "s.tif")])
    assert result.exit_code == 0, result.output
    record = tmp_path / ".s.tif.plenocli.json"
    assert (tmp_path / "victim.txt").read_text() == "keep"
    assert not record.is_symlink() and '"stage": "decode"' in record.read_text()


@pytest.mark.parametrize("value, said", [("!!binary OQ==", "binary data (!!binary, 1 byte)"),
                                         ("!!set {1}", "a set (!!set) of 1 value")])
def test_a_simulate_param_of_another_kind_is_said_in_words(value, said, tmp_path):
    # audit 19a M1: "noise = b'9' is not a finite number"
    result = CliRunner().invoke(cli, ["simulate", "dualpixel", "-o", str(tmp_path / "sx"),
                                      "--pixels", "32", "--param", f"noise={value}"])
    assert_one_line(result, 2, (f"noise = {said} is not",))
    assert "b'" not in result.output and not (tmp_path / "sx").exists()
