"""`plenocli simulate` end to end: every kind at a small size, options, errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.synth import KIND_NAMES, kinds

# the smallest options each kind accepts, and the files it must write besides truth.json
GHOST_QUAD = {"capture.tif", "clean.tif", "masked_S00.tif", "masked_S01.tif", "masked_S10.tif",
              "masked_S11.tif"}
SMALL = {
    "dualpixel": (["--pixels", "32x48"], {"capture.dng", "white.dng", "truth.npz"}),
    "dualpixel-ghost": (["--pixels", "48"], {"capture.dng", "clean.dng", "white.dng",
                                             "masked_A.dng", "masked_B.dng"}),
    "quadpixel-ghost": (["--pixels", "32"], GHOST_QUAD),
    "quadpixel-ghost-mask": (["--pixels", "32"], GHOST_QUAD),
    "raytrix-ghost": (["--pixels", "60"], {"capture.tif", "clean.tif", "white.tif",
                                           "masked_left.tif", "masked_right.tif"}),
    "dualpixel-masked": (["--pixels", "48"], {"capture.dng"}),
    "dualpixel-prism": (["--pixels", "48"], {"capture.dng"}),
    "dualpixel-white": (["--pixels", "48"], {"capture.dng"}),
    "hexgrid-white": (["--param", "size=96"], {"white.tif", "grid_true.xml"}),
    "quad-rig": (["--param", "view_shape=[48, 64]"],
                 {"views.tif", "white_S00.tif", "white_S01.tif", "white_S10.tif",
                  "white_S11.tif"}),
    "quadpixel-masked": (["--pixels", "32"], {"capture.tif"}),
    "quadpixel-pyramid": (["--pixels", "32", "--rays", "2"], {"capture.tif"}),
    "quadpixel-white": (["--pixels", "32"], {"capture.tif"}),
    "raytrix-prism": (["--pixels", "60"], {"capture.tif"}),
    "raytrix-scene": (["--param", "rows=48", "--param", "cols=64"],
                      {"frames.tif", "grid.yaml", "texture.tif"}),
    "raytrix-white": (["--pixels", "60"], {"capture.tif"}),
    "lenslet-depth": (["--pixels", "96x128"], {"frames.tif", "grid.yaml", "depth.tif"}),
    "dualpixel-depth": (["--pixels", "64"], {"views.tif", "disparity.tif"}),
    "quadpixel-depth": (["--pixels", "64"], {"views.tif", "disparity.tif"}),
    "stereo-rig": (["--param", "view_shape=[48, 64]"], {"views.tif", "white_L.tif",
                                                         "white_R.tif"}),
}


def invoke(*args):
    return CliRunner().invoke(cli, ["simulate", *map(str, args)])


def test_every_kind_is_listed_and_tested():
    assert tuple(sorted(kinds())) == KIND_NAMES == tuple(sorted(SMALL))


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_every_kind_writes_its_files_and_truth(tmp_path, kind):
    options, files = SMALL[kind]
    out = tmp_path / kind
    res = invoke(kind, "-o", out, "--seed", 3, *options)
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} == files | {"truth.json"}
    truth = json.loads((out / "truth.json").read_text())  # strict JSON (no NaN)
    record = truth["provenance"]
    assert record["stage"] == "simulate" and record["parameters"]["kind"] == kind
    assert record["parameters"]["seed"] == 3
    assert not list(out.glob("*.tmp*"))


def test_same_seed_same_capture(tmp_path):
    for name in ("a", "b"):
        assert invoke("quadpixel-pyramid", "-o", tmp_path / name, "--pixels", 32).exit_code == 0
    a, b = ((tmp_path / n / "capture.tif").read_bytes() for n in ("a", "b"))
    assert a == b


def test_options_reach_the_generator(tmp_path):
    from plenocli.io.raw import decode

    res = invoke("dualpixel-masked", "-o", tmp_path, "--pixels", 48, "--param", "crosstalk=0.25",
                 "--param", "noise_dn=0")
    assert res.exit_code == 0, res.output
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["crosstalk"] == 0.25
    frames, _ = decode(tmp_path / "capture.dng")
    top, left, bottom, right = truth["active_area"]
    s = frames[0, top:bottom, left:right].astype(float) - truth["black_level"]
    a = frames[1, top:bottom, left:right].astype(float) - truth["black_level"]
    assert (s - a).sum() / a.sum() == pytest.approx(0.25, rel=0.01)
    assert np.all(frames[:, :, :left] == truth["black_level"])


@pytest.mark.parametrize("args, code, words", [
    # every bad value is a usage error (audit 7 E11: the kind's own values were exit 1)
    (["quadpixel-pyramid", "--param", "colour=1"], 2, "does not take 'colour'"),
    (["quadpixel-pyramid", "--param", "crosstalk"], 2, "expected KEY=VALUE"),
    (["quadpixel-pyramid", "--pixels", "15"], 2, "pixels 15"),
    (["dualpixel", "--pixels", "wide"], 2, "ROWSxCOLS"),
    (["dualpixel", "--pixels", "-5"], 2, "'-5' is not one positive whole number"),
    (["hexgrid-white", "--param", "pitch_px=1000"], 2, "pitch_px must be"),
    (["hexgrid-white", "--param", "size="], 2, "no value after '='"),
    (["hexgrid-white", "--param", "pitch_px=12 # c"], 2, "'# c' as a comment"),
    (["moon-rig"], 2, "moon-rig"),
    (["quadpixel-pyramid", "--rays", "0"], 2, "rays"),
])
def test_bad_options_are_one_line_and_leave_nothing(tmp_path, args, code, words):
    out = tmp_path / "out"
    res = invoke(args[0], "-o", out, *args[1:])
    assert res.exit_code == code, res.output
    assert words in res.output
    if code == 1:
        assert len(res.output.strip().splitlines()) == 1
    assert not out.exists()


def test_help_does_not_import_the_simulator():
    code = ("import sys\nfrom click.testing import CliRunner\nfrom plenocli.cli.main import cli\n"
            "res = CliRunner().invoke(cli, ['simulate', '--help'])\n"
            "assert res.exit_code == 0 and 'quadpixel-pyramid' in res.output\n"
            "print(sorted(m for m in sys.modules if m.startswith(('plenocli.synth.', 'cv2', "
            "'tifffile', 'scipy.ndimage'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_a_failed_write_leaves_nothing(tmp_path, monkeypatch):
    from plenocli.io import simfiles

    real = simfiles.write_file

    def failing(path, item, record):
        if item.name == "white.dng":  # the second file of the set
            raise OSError("disk full")
        real(path, item, record)

    monkeypatch.setattr(simfiles, "write_file", failing)
    out = tmp_path / "set"
    res = invoke("dualpixel", "-o", out, "--pixels", "32x48")
    assert res.exit_code == 1 and "disk full" in res.output
    assert not out.exists()
    out.mkdir()
    (out / "keep.txt").write_text("the user's")
    assert invoke("dualpixel", "-o", out, "--pixels", "32x48").exit_code == 1
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


def test_a_pipeline_step_can_simulate(tmp_path):
    from plenocli.pipeline.config import load_config
    from plenocli.pipeline.runner import run_pipeline

    config = tmp_path / "sim.yaml"
    config.write_text("steps:\n  simulate:\n    kind: stereo-rig\n    output: rig\n"
                      "    seed: 4\n    param: ['view_shape=[48, 64]']\n")
    run_pipeline(load_config(config))
    truth = json.loads((tmp_path / "rig" / "truth.json").read_text())
    assert truth["seed"] == 4 and truth["view_shape"] == [48, 64]


def test_a_folder_filled_again_holds_one_simulation_not_two(tmp_path):
    # audit 7 E19: hexgrid-white's white.tif and grid_true.xml stayed beside dualpixel's truth
    out = tmp_path / "sim"
    assert invoke("hexgrid-white", "-o", out, "--param", "size=100").exit_code == 0
    assert {"white.tif", "grid_true.xml"} <= {p.name for p in out.iterdir()}
    (out / "mine.txt").write_text("the user's")
    (out / "grid_true.xml").write_text("edited since")   # changed since plenocli wrote it: kept
    assert invoke("dualpixel", "-o", out, "--pixels", 64).exit_code == 0
    names = {p.name for p in out.iterdir()}
    assert "white.tif" not in names and {"mine.txt", "grid_true.xml", "capture.dng"} <= names
    assert json.loads((out / "truth.json").read_text())["kind"] == "dualpixel"
    assert invoke("dualpixel", "-o", out, "--pixels", 64).exit_code == 0   # same set again
    assert {p.name for p in out.iterdir()} == names


def test_a_folder_given_as_a_link_gets_its_record_and_is_filled_again_whole(tmp_path):
    """audit 8 P1: through a symbolic link to a folder no record was written (the files landed
    under the link, the record was looked for under its target), so a second simulation left
    the first one's files beside its own."""
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "real")
    assert invoke("hexgrid-white", "-o", tmp_path / "link", "--param", "size=100").exit_code == 0
    assert (tmp_path / ".link.plenocli.json").is_file()
    assert invoke("dualpixel", "-o", tmp_path / "link", "--pixels", 64).exit_code == 0
    names = {p.name for p in (tmp_path / "real").iterdir()}
    assert "white.tif" not in names and "capture.dng" in names


def test_a_run_filling_a_folder_another_run_fills_waits_for_it(tmp_path):
    """Two simulate runs into one folder at the same moment each read the folder's record
    before the other landed, and each kept the other's files: a mixed set, both exit 0 (5 of
    16 tries). A run now waits while another fills the folder (the lock held here)."""
    import subprocess
    import sys

    from plenocli.io.folderlock import folders_locked

    out = tmp_path / "cc"
    with folders_locked([out]):
        proc = subprocess.Popen([sys.executable, "-m", "plenocli", "simulate", "hexgrid-white",
                                 "-o", str(out), "--param", "size=100"],
                                stderr=subprocess.PIPE, text=True)
        first = proc.stderr.readline()
        assert "waiting for another run writing into" in first, first
        assert not (out / "truth.json").exists()
    assert proc.wait(timeout=120) == 0, proc.stderr.read()
    assert sorted(p.name for p in out.iterdir()) == ["grid_true.xml", "truth.json", "white.tif"]


def test_the_record_holds_the_kinds_parameters_defaults_included(tmp_path):
    """The record and truth.json's provenance held only the options given (--param size=96),
    not the kind's own defaults (pitch, angle, jitter): every output records its fully
    resolved parameters."""
    from plenocli.pipeline.registry import get_stages

    out = tmp_path / "hx"
    result = CliRunner().invoke(cli, ["simulate", "hexgrid-white", "-o", str(out), "--param",
                                      "size=96"])
    assert result.exit_code == 0, result.output
    want = {"size": 96, "pitch_px": 20.2, "angle_deg": 7.0, "jitter_px": 0.05, "cfa": "RGGB",
            "lattice": "hex", "seed": 0}
    record = json.loads((tmp_path / ".hx.plenocli.json").read_text())
    assert record["parameters"]["kind_parameters"] == want
    provenance = json.loads((out / "truth.json").read_text())["provenance"]["parameters"]
    assert {k: provenance[k] for k in want} == want
    params = {"kind": "hexgrid-white", "output": str(out), "seed": 0, "pixels": None,
              "rays": None, "no_prisms": False, "param": ("size=96",)}
    assert get_stages()["simulate"].why_stale(params) is None   # up to date as recorded


@pytest.mark.parametrize("first", ["real", "link"])
def test_a_folder_filled_by_its_name_and_through_a_link_holds_one_set(tmp_path, first):
    """The earlier run's files are removed by what its record lists; the record was keyed by
    the name given, so a run through a symbolic link to the folder (or by the folder's own
    name after one through a link) found none and left a mixed set, exit 0."""
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real)
    names = [real, link] if first == "real" else [link, real]
    runner = CliRunner()
    for out, kind, extra in ((names[0], "lenslet-depth", []),
                             (names[1], "hexgrid-white", ["--param", "size=96"])):
        result = runner.invoke(cli, ["simulate", kind, "-o", str(out), *extra])
        assert result.exit_code == 0, result.output
    assert sorted(p.name for p in real.iterdir()) == ["grid_true.xml", "truth.json",
                                                       "white.tif"]


@pytest.mark.parametrize("kind", KIND_NAMES)
def test_no_kind_renders_a_capture_of_a_few_pixels(kind, tmp_path):
    """audit 12 I1: raytrix-ghost rendered --pixels 2 as a 1 x 2 capture of zeros (exit 0) and
    failed on 1 as an internal error; every kind refuses sizes it cannot render (or --pixels
    itself), a usage error."""
    for pixels in ("1", "2"):
        res = CliRunner().invoke(cli, ["simulate", kind, "-o", str(tmp_path / pixels),
                                       "--pixels", pixels])
        assert res.exit_code == 2, (kind, pixels, res.output)
        assert not (tmp_path / pixels).exists()
