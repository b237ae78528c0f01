"""The make-style rule for every output kind: each output's record (a sidecar written with it)
says how it was made; an output without a readable, matching record makes its step run again."""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import InputError
from plenocli.pipeline.config import load_config
from plenocli.pipeline.runner import plan, run_pipeline

ROOT = Path(__file__).resolve().parents[1]


def ran(decisions):
    return [d.step.name for d in decisions if d.run]


def reason(decisions, name):
    return next(d.reason for d in decisions if d.step.name == name)


@pytest.fixture
def built(project):
    """The demo pipeline run once: every step up to date."""
    run_pipeline(load_config(project))
    assert ran(plan(load_config(project))) == []
    return project


def out_dir(project: Path) -> Path:
    return project.parent.parent / "out" / "demo" / "dualpixel"


def test_a_changed_parameter_reruns_a_step_whose_outputs_are_jpeg_and_png(built):
    decisions = plan(load_config(built, ["develop.exposure=3"]))
    assert ran(decisions) == ["develop"]
    assert reason(decisions, "develop") == "parameter exposure changed (0.0 -> 3.0)"


def test_an_output_replaced_by_a_foreign_file_reruns_its_step(built):
    photo = out_dir(built) / "S.jpg"
    shutil.copy(ROOT / "docs" / "img" / "panorama_dualpixel.jpg", photo)  # newer than inputs
    decisions = plan(load_config(built))
    assert ran(decisions) == ["develop"]
    assert "S.jpg changed since it was made" in reason(decisions, "develop")


def test_an_output_without_a_record_reruns_its_step(built):
    sidecar = out_dir(built) / ".capture_raw.png.plenocli.json"
    assert sidecar.is_file()
    sidecar.unlink()
    decisions = plan(load_config(built))
    assert ran(decisions)[0] == "decode"
    assert "no record of how capture_raw.png was made" in reason(decisions, "decode")
    sidecar.write_text("{not json")
    assert ran(plan(load_config(built)))[0] == "decode"


def test_another_input_file_older_than_the_outputs_reruns_the_step(built):
    other = built.parent.parent / "fixtures" / "dualpixel" / "white_copy.dng"
    shutil.copy(built.parent.parent / "fixtures" / "dualpixel" / "white.dng", other)
    past = time.time() - 3600
    os.utime(other, (past, past))  # older than every output: mtimes alone would skip it
    decisions = plan(load_config(built, [f"decode_white.input={other}"]))
    assert ran(decisions)[0] == "decode_white"
    assert reason(decisions, "decode_white") == ("white_copy.dng is not the input file "
                                                 "white_frames.tif was made from (size, time or "
                                                 "content)")


def _same_size_and_time(path: Path) -> None:
    """Another content of ``path``'s size, its times kept (a burst frame off a card, copied
    with cp -p)."""
    st = path.stat()
    data = bytearray(path.read_bytes())
    data[-100:] = bytes(255 - b for b in data[-100:])
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.stat().st_size == st.st_size and path.stat().st_mtime_ns == st.st_mtime_ns


def test_a_file_replaced_by_another_of_the_same_size_and_time_reruns_its_step(built):
    _same_size_and_time(built.parent.parent / "fixtures" / "dualpixel" / "capture.dng")
    decisions = plan(load_config(built))
    assert ran(decisions) == ["decode", "bias", "flat", "develop"]
    assert "capture.dng is not the input file" in reason(decisions, "decode")
    run_pipeline(load_config(built))
    _same_size_and_time(out_dir(built) / "S.jpg")
    assert "S.jpg changed since it was made" in reason(plan(load_config(built)), "develop")


def test_an_input_restored_to_an_older_copy_reruns_the_step(built):
    capture = built.parent.parent / "fixtures" / "dualpixel" / "capture.dng"
    past = time.time() - 3600
    os.utime(capture, (past, past))
    decisions = plan(load_config(built))
    assert ran(decisions) == ["decode", "bias", "flat", "develop"]
    assert "capture.dng is not the input file" in reason(decisions, "decode")


def test_a_step_run_from_the_shell_is_up_to_date_for_the_runner(built, monkeypatch):
    steps = load_config(built, ["bias.smooth=3"])
    bias = next(s for s in steps if s.name == "bias")
    monkeypatch.chdir(out_dir(built))
    result = CliRunner().invoke(cli, ["bias", "capture_frames.tif", "--smooth", "3", "-o",
                                      "capture_biased.tif", "--preview", "biased_A_B.png", "-q"])
    assert result.exit_code == 0, result.output
    decisions = plan(steps)
    assert reason(decisions, "bias") == "up to date"
    assert ran(decisions) == ["flat", "develop"]  # bias' output is newer than theirs
    assert bias.params["smooth"] == 3


def test_a_folder_output_has_a_record_too(tmp_path):
    config = tmp_path / "sim.yaml"
    config.write_text("steps:\n  simulate:\n    kind: dualpixel\n    pixels: 32x48\n"
                      "    output: sim\n")
    assert ran(run_pipeline(load_config(config))) == ["simulate"]
    assert ran(plan(load_config(config))) == []
    assert ran(plan(load_config(config, ["simulate.seed=2"]))) == ["simulate"]
    (tmp_path / "sim" / "white.dng").write_bytes(b"not the simulated white")
    assert "changed since it was made" in reason(plan(load_config(config)), "simulate")


def test_a_project_moved_with_its_times_stays_up_to_date(built, tmp_path_factory):
    moved = tmp_path_factory.mktemp("elsewhere") / "project"
    shutil.copytree(built.parent.parent, moved, symlinks=True)  # copy2: times kept
    config = moved / "configs" / built.name
    assert ran(plan(load_config(config))) == []
    os.utime(moved / "fixtures" / "dualpixel" / "white.dng")  # now it is another white
    assert ran(plan(load_config(config)))[:2] == ["decode_white", "bias_white"]


def test_swapping_two_outputs_reruns_the_step(built):
    steps = load_config(built, ["flat.save_gain=../out/demo/dualpixel/views.tif",
                                "flat.output=../out/demo/dualpixel/gain.tif",
                                # develop follows the views (a gain map is no image to develop)
                                "develop.input=../out/demo/dualpixel/gain.tif"])
    decisions = plan(steps)
    assert reason(decisions, "flat") == "gain.tif was made as flat save_gain"


def test_a_hash_started_ahead_is_the_file_s_and_follows_a_change(tmp_path):
    import hashlib

    from plenocli.model.provenance import hash_ahead, sha256_file

    path = tmp_path / "a.bin"
    path.write_bytes(bytes(range(256)) * 40000)
    hash_ahead([path, tmp_path / "missing.tif"])
    assert sha256_file(path) == hashlib.sha256(path.read_bytes()).hexdigest()
    path.write_bytes(b"changed")
    os.utime(path, ns=(1, 1))
    hash_ahead([path])
    assert sha256_file(path) == hashlib.sha256(b"changed").hexdigest()


def test_a_record_leaves_out_the_parameters_the_provenance_leaves_out(built):
    """audit 9 P3: records listed parameters without effect in the run (flat's --percentile with
    --reference max) that the output's own provenance leaves out; now both agree (and the
    pipeline, built, is still up to date: the comparison leaves them out too)."""
    import json

    from plenocli.io import tiffio

    views = out_dir(built) / "views.tif"
    recorded = json.loads((views.parent / ".views.tif.plenocli.json").read_text())["parameters"]
    provenance = tiffio.read_meta(views)["provenance"]["parameters"]
    assert "percentile" not in recorded and "percentile" not in provenance
    assert set(recorded) <= set(provenance)
    photo = json.loads((views.parent / ".S.jpg.plenocli.json").read_text())["parameters"]
    assert "wb" not in photo  # --wb-from gives the white balance


def test_a_record_of_a_value_as_typed_compares_as_the_value_it_stands_for(tmp_path):
    # audit 22c M2: an older record holds refocus --g as typed ('2 : 6 : 0.5'); the same g
    # resolved now ('2:6:0.5') is the same parameter, not a change that reruns the step
    from plenocli.pipeline import records
    from plenocli.pipeline.registry import get_stages

    stage = get_stages()["refocus"]
    for name in ("in.tif", "g.yaml", "out.tif"):
        (tmp_path / name).write_bytes(name.encode())
    params = stage.resolve({"input": str(tmp_path / "in.tif"), "grid": str(tmp_path / "g.yaml"),
                            "output": str(tmp_path / "out.tif"), "g": " 2 : 6 : 0.5 "})
    assert params["g"] == "2:6:0.5"
    inputs, outputs = stage.by_role(params, stage.inputs), stage.by_role(params, stage.outputs)
    out = tmp_path / "out.tif"
    records.write_records("refocus", {**stage.recorded(params), "g": "2 : 6 : 0.5"}, inputs,
                          outputs, records.input_states(inputs), [(out, out)])
    assert stage.why_stale(params) is None
    changed = stage.resolve({**{k: params[k] for k in ("input", "grid", "output")}, "g": "2:6:1"})
    assert "parameter g changed (2:6:0.5 -> 2:6:1)" in stage.why_stale(changed)


def test_a_made_project_on_a_read_only_file_system_is_up_to_date(built, monkeypatch):
    """audit 24 F1: `run` of a project made and then archived read-only (a snapshot, an NFS
    export) exited 1 "folder not writable" where `--dry-run` and make said up to date: with
    nothing to write there is nothing to lock. A step that must run is still refused."""
    from plenocli.io import atomic

    real_access = os.access
    outputs = out_dir(built).resolve()
    monkeypatch.setattr(atomic.os, "access",  # root ignores permission bits: say it is read-only
                        lambda p, mode: False if Path(p).resolve() == outputs
                        else real_access(p, mode))
    assert ran(run_pipeline(load_config(built), locked=True)) == []
    with pytest.raises(InputError, match="cannot write .*S.jpg.*not writable"):
        run_pipeline(load_config(built, ["develop.exposure=3"]), locked=True)
