"""Batches: the template convention, the process pool, failures, reruns and Ctrl-C."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tifffile
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.errors import ConfigError, InputError
from plenocli.io.dng import write_dng
from plenocli.pipeline.batch import format_summary, run_batch
from plenocli.pipeline.captures import expand_inputs
from plenocli.pipeline.config import load_config, read_template
from plenocli.synth.dualpixel import dng_options, dualpixel_capture

ROOT = Path(__file__).resolve().parents[1]
N_CAPTURES = 12
CORRUPT = "shot07"
GEOMETRY = dict(rows=48, cols=64, top=8, left=16)

TEMPLATE = """\
out: out
steps:
  decode_white:
    stage: decode
    input: {white}
    output: "{{out}}/white_frames.tif"
  bias_white:
    stage: bias
    input: "{{out}}/white_frames.tif"
    smooth: 3
    output: "{{out}}/white_biased.tif"
  gain:
    stage: flat
    input: "{{out}}/white_biased.tif"
    white: "{{out}}/white_biased.tif"
    median: 3
    save-gain: "{{out}}/gain.tif"
    output: "{{out}}/white_flat.tif"
  decode:
    input: "{{capture}}"
    output: "{{out}}/{{name}}/frames.tif"
  bias:
    input: "{{out}}/{{name}}/frames.tif"
    smooth: 3
    output: "{{out}}/{{name}}/biased.tif"
  flat:
    input: "{{out}}/{{name}}/biased.tif"
    gain: "{{out}}/gain.tif"
    output: "{{out}}/{{name}}/views.tif"
"""
PER_CAPTURE_OUTPUTS = ("frames.tif", "biased.tif", "views.tif")


def make_shoot(folder: Path, n: int = N_CAPTURES, *, corrupt: str | None = CORRUPT,
               **geometry) -> tuple[Path, list[Path]]:
    """``n`` synthetic dual-pixel captures, a white image and a batch template in ``folder``."""
    geo = {**GEOMETRY, **geometry}
    folder.mkdir(parents=True, exist_ok=True)
    raw, truth = dualpixel_capture(seed=1000, scene="white", **geo)
    write_dng(folder / "white.dng", raw, **dng_options(truth))
    captures = []
    for k in range(n):
        path = folder / "captures" / f"shot{k:02d}.dng"
        path.parent.mkdir(exist_ok=True)
        raw, truth = dualpixel_capture(seed=k, **geo)
        write_dng(path, raw, **dng_options(truth))
        if path.stem == corrupt:
            data = path.read_bytes()
            path.write_bytes(data[: len(data) // 3])  # truncated mid-frame
        captures.append(path)
    config = folder / "batch.yaml"
    config.write_text(TEMPLATE.format(white=folder / "white.dng"))
    return config, captures


def concrete_config(folder: Path, capture: Path, out: Path) -> Path:
    """The template written out for one capture, as a user would for plenocli run."""
    text = TEMPLATE.format(white=folder / "white.dng").replace("out: out\n", "")
    text = text.replace("{capture}", str(capture)).replace("{name}", capture.stem)
    config = folder / "single" / f"{capture.stem}.yaml"
    config.parent.mkdir(exist_ok=True)
    config.write_text(text.replace("{out}", str(out)))
    return config


def pixels(path: Path) -> np.ndarray:
    with tifffile.TiffFile(path) as tif:
        return np.stack([page.asarray() for page in tif.pages])


def mtimes(folder: Path) -> dict[str, int]:
    return {str(p): p.stat().st_mtime_ns for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def shoot(tmp_path_factory):
    folder = tmp_path_factory.mktemp("shoot")
    config, captures = make_shoot(folder)
    return folder, config, captures


@pytest.fixture(scope="module")
def sequential(shoot):
    """Reference outputs: one `plenocli run` per capture, each with its own concrete config."""
    folder, _, captures = shoot
    out = folder / "sequential"
    codes = {}
    for capture in captures:
        result = CliRunner().invoke(cli, ["run", "-q", str(concrete_config(folder, capture, out))])
        codes[capture.stem] = result.exit_code
    return out, codes


@pytest.fixture(scope="module")
def batch_run(shoot):
    folder, config, _ = shoot
    out = folder / "batch"
    args = ["batch", str(config), "--inputs", str(folder / "captures" / "*.dng"), "-j", "2",
            "--out", str(out)]
    first = CliRunner().invoke(cli, args)
    before = mtimes(out)
    second = CliRunner().invoke(cli, args)
    return out, first, second, before, args


def test_batch_matches_sequential_runs(shoot, sequential, batch_run):
    _, _, captures = shoot
    seq_out, codes = sequential
    out, first, *_ = batch_run
    assert codes[CORRUPT] == 1 and sum(c == 0 for c in codes.values()) == N_CAPTURES - 1
    for capture in captures:
        if capture.stem == CORRUPT:
            continue
        for name in PER_CAPTURE_OUTPUTS:
            got = pixels(out / capture.stem / name)
            want = pixels(seq_out / capture.stem / name)
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want, err_msg=f"{capture.stem}/{name}")
    # every capture got its own outputs: no two captures' views are the same
    views = [pixels(out / c.stem / "views.tif") for c in captures if c.stem != CORRUPT]
    assert all(not np.array_equal(views[0], v, equal_nan=True) for v in views[1:])


def test_corrupt_capture_fails_alone_with_its_reason(batch_run):
    out, first, *_ = batch_run
    assert first.exit_code == 1
    failures = [ln for ln in first.stderr.splitlines() if ln.startswith("failed: ")]
    assert len(failures) == 1 and f"{CORRUPT}.dng" in failures[0]
    assert "step 'decode'" in failures[0] and "truncated" in failures[0]
    table = {ln.split()[0]: ln.split()[1] for ln in first.stderr.splitlines()
             if ln.startswith("shot")}
    assert table[CORRUPT] == "failed"
    assert [s for n, s in table.items() if n != CORRUPT] == ["done"] * (N_CAPTURES - 1)
    assert f"{N_CAPTURES} captures: {N_CAPTURES - 1} done, 0 skipped" in first.stderr
    assert "Error: 1 of 12 captures failed" in first.stderr
    assert not (out / CORRUPT).exists() or not any((out / CORRUPT).iterdir())
    assert not list(out.rglob("*.part"))


def test_rerun_does_no_work(batch_run):
    out, _, second, before, _ = batch_run
    assert mtimes(out) == before  # nothing rewritten
    assert second.exit_code == 1  # the corrupt capture still fails, and only it
    table = {ln.split()[0]: ln.split()[1] for ln in second.stderr.splitlines()
             if ln.startswith("shot")}
    assert [s for n, s in table.items() if n != CORRUPT] == ["skipped"] * (N_CAPTURES - 1)
    assert "shared steps run: none (up to date)" in second.stderr


def test_rerun_after_fixing_redoes_only_the_missing_capture(tmp_path):
    config, captures = make_shoot(tmp_path, 3, corrupt="shot01")
    out = tmp_path / "out"
    report = run_batch(config, captures, out=out, jobs=2)
    assert [r.status for r in report.results] == ["done", "failed", "done"]
    before = mtimes(out)
    raw, truth = dualpixel_capture(seed=1, **GEOMETRY)
    write_dng(captures[1], raw, **dng_options(truth))  # the photographer copies the file again
    report = run_batch(config, captures, out=out, jobs=2)
    assert [r.status for r in report.results] == ["skipped", "done", "skipped"]
    assert report.results[1].detail == "decode, bias, flat"
    after = mtimes(out)
    assert {k: v for k, v in after.items() if k in before} == before


def test_changed_shared_input_reruns_every_capture(tmp_path):
    config, captures = make_shoot(tmp_path, 2, corrupt=None)
    out = tmp_path / "out"
    run_batch(config, captures, out=out, jobs=1)
    report = run_batch(config, captures, out=out, jobs=1, overrides=["bias_white.smooth=5"])
    assert [d.step.name for d in report.shared if d.run] == ["bias_white", "gain"]
    assert [r.detail for r in report.results] == ["flat", "flat"]  # only what uses the white


def test_dry_run_writes_nothing(tmp_path):
    config, captures = make_shoot(tmp_path, 2, corrupt=None)
    report = run_batch(config, captures, out=tmp_path / "out", dry_run=True, jobs=2)
    assert [r.status for r in report.results] == ["would run", "would run"]
    assert not (tmp_path / "out").exists()
    assert "2 would run" in format_summary(report)
    one = run_batch(config, captures[:1], out=tmp_path / "out", dry_run=True, jobs=1)
    assert format_summary(one).splitlines()[-1].startswith("1 capture: 0 done")  # not captures


def test_one_job_and_two_jobs_agree(tmp_path):
    config, captures = make_shoot(tmp_path, 3, corrupt=None)
    run_batch(config, captures, out=tmp_path / "one", jobs=1)
    run_batch(config, captures, out=tmp_path / "two", jobs=2)
    for c in captures:
        np.testing.assert_array_equal(pixels(tmp_path / "one" / c.stem / "views.tif"),
                                      pixels(tmp_path / "two" / c.stem / "views.tif"))


# ----------------------------------------------------------------------- the template convention

def test_template_shared_and_per_capture_steps(shoot):
    folder, config, captures = shoot
    template = read_template(config)
    assert template.per_capture_steps() == {"decode", "bias", "flat"}
    steps = template.steps(capture=captures[0], out=folder / "o", only="per-capture")
    assert [s.name for s in steps] == ["decode", "bias", "flat"]
    assert steps[0].params["input"] == str(captures[0].resolve())
    assert steps[2].params["output"] == str((folder / "o" / "shot00" / "views.tif").resolve())
    assert steps[2].params["gain"] == str((folder / "o" / "gain.tif").resolve())
    shared = template.steps(out=folder / "o", only="shared")
    assert [s.name for s in shared] == ["decode_white", "bias_white", "gain"]
    # the config's own 'out: out' is relative to the config's folder
    default = template.steps(only="shared")[0].params["output"]
    assert default == str((folder / "out" / "white_frames.tif").resolve())


def test_load_config_refuses_a_template(shoot):
    _, config, _ = shoot
    with pytest.raises(ConfigError, match="batch template.*plenocli batch"):
        load_config(config)


def test_unquoted_placeholder_is_understood(tmp_path):
    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    config.write_text(config.read_text().replace('input: "{capture}"', "input: {capture}"))
    steps = read_template(config).steps(capture=captures[0], only="per-capture")
    assert steps[0].params["input"] == str(captures[0].resolve())


@pytest.mark.parametrize("edit, message", [
    (('"{out}/{name}/views.tif"', '"{out}/views.tif"'), "writes output.*for every capture"),
    (("out: out\n", ""), r"uses \{out\}; give --out DIR"),
])
def test_template_errors(tmp_path, edit, message):
    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    config.write_text(config.read_text().replace(*edit))
    with pytest.raises(ConfigError, match=message):
        run_batch(config, captures)


def test_config_without_capture_placeholder_is_not_a_batch(tmp_path):
    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    single = concrete_config(tmp_path, captures[0], tmp_path / "o")
    with pytest.raises(ConfigError, match="nothing to run per capture"):
        run_batch(single, captures)


def test_expand_inputs(tmp_path):
    for name in ("b.dng", "a.dng", "c.txt"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "list.txt").write_text("# shoot\nc.txt\n\na.dng\n")
    got = expand_inputs([str(tmp_path / "*.dng"), f"@{tmp_path / 'list.txt'}"])
    assert got == [tmp_path / "a.dng", tmp_path / "b.dng", tmp_path / "c.txt"]
    with pytest.raises(InputError, match="matches no file"):
        expand_inputs([str(tmp_path / "*.CR2")])
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.dng").write_bytes(b"x")
    with pytest.raises(InputError, match="same name 'a'"):
        expand_inputs([str(tmp_path / "a.dng"), str(tmp_path / "sub" / "a.dng")])


def test_a_capture_is_named_as_given_and_a_file_by_two_names_runs_once(shoot, tmp_path,
                                                                        caplog):
    """audit 20 M4: a capture given through a link took its target's {name}, and a link in the
    glob of its target vanished without a word (a hard link ran twice)."""
    folder, config, captures = shoot
    keep = tmp_path / "keepers"
    keep.mkdir()
    (keep / "best.dng").symlink_to(captures[0])
    got = expand_inputs([str(keep / "*.dng")])
    assert got == [keep.resolve() / "best.dng"]
    report = run_batch(config, got, out=tmp_path / "o", dry_run=True)
    assert [r.name for r in report.results] == ["best"]
    steps = read_template(config).steps(capture=got[0], out=tmp_path / "o", only="per-capture")
    assert steps[-1].params["output"] == str((tmp_path / "o" / "best" / "views.tif").resolve())
    shoot2 = tmp_path / "shoot2"
    shoot2.mkdir()
    (shoot2 / "a.dng").write_bytes(captures[0].read_bytes())
    (shoot2 / "b.dng").symlink_to("a.dng")
    os.link(shoot2 / "a.dng", shoot2 / "c.dng")
    (shoot2 / "d.dng").write_bytes(captures[0].read_bytes())  # a copy is a capture of its own
    with caplog.at_level("WARNING", logger="plenocli"):
        got = expand_inputs([str(shoot2 / "*.dng"), str(keep / "best.dng")])
    assert [p.name for p in got] == ["a.dng", "d.dng", "best.dng"]
    said = [r.getMessage() for r in caplog.records if "same file" in r.getMessage()]
    assert len(said) == 1 and "b.dng" in said[0] and "c.dng" in said[0] and "'a'" in said[0]


def test_a_capture_in_a_link_loop_is_said_in_one_line(shoot, tmp_path):
    """A capture that is a symbolic-link loop was an 'internal error: RuntimeError' (a loop in
    its folder stopped the batch so); now its step says so, or the batch before any work."""
    _, config, _ = shoot
    (tmp_path / "loop.dng").symlink_to("loop.dng")
    report = run_batch(config, [tmp_path / "loop.dng"], out=tmp_path / "o", dry_run=True)
    assert "a symbolic link loop" in report.results[0].detail
    (tmp_path / "la").symlink_to("lb")
    (tmp_path / "lb").symlink_to("la")
    with pytest.raises(InputError, match="its folder is a symbolic-link loop"):
        expand_inputs([str(tmp_path / "la" / "x.dng")])


def test_a_glob_that_matches_the_batchs_own_outputs_leaves_them_out(tmp_path):
    # audit 8 E12: the second run took the first run's outputs under --out for captures
    config, captures = make_shoot(tmp_path, 2, corrupt=None)
    out = tmp_path / "captures" / "out"
    args = ["batch", str(config), "--inputs", str(tmp_path / "captures" / "**" / "*"),
            "--out", str(out), "-j", "1"]
    first = CliRunner().invoke(cli, args)
    assert first.exit_code == 0, first.output
    assert (out / "shot01" / "views.tif").is_file() and (out / "gain.tif").is_file()
    second = CliRunner().invoke(cli, args)
    assert second.exit_code == 0, second.output
    assert "2 captures: 0 done, 2 skipped" in second.output
    template = read_template(config)
    got = expand_inputs([str(tmp_path / "captures" / "**" / "*")], template=template,
                        out=str(out))
    assert got == captures
    with pytest.raises(InputError, match="matches only files this batch writes"):
        expand_inputs([str(out / "**" / "*.tif")], template=template, out=str(out))
    # a file under --out that the batch does not write is a capture like any other
    (out / "extra.dng").write_bytes(captures[0].read_bytes())
    assert expand_inputs([str(out / "*")], template=template, out=str(out)) == [
        out / "extra.dng"]


@pytest.mark.parametrize("text", ["", "# nothing yet\n\n"])
def test_an_empty_list_of_captures_is_named_so(tmp_path, text):
    # audit 7 E9: '@empty.txt' was told it "matches no file; quote globs"
    (tmp_path / "list.txt").write_text(text)
    with pytest.raises(InputError, match="list.txt lists no captures") as err:
        expand_inputs([f"@{tmp_path / 'list.txt'}"])
    assert "glob" not in str(err.value)


def test_a_failed_capture_is_told_to_run_alone_as_a_batch(shoot, tmp_path):
    # audit 7 E18: the advice was "plenocli run", which refuses a batch template
    from plenocli.pipeline import batch

    folder, config, captures = shoot
    for message in (batch.timed_out(0.5), batch.CRASHED):
        assert "plenocli run" not in message
        assert "plenocli batch CONFIG --inputs CAPTURE -j 1" in message
    alone = CliRunner().invoke(cli, ["batch", str(config), "--inputs", str(captures[0]), "-j",
                                     "1", "--out", str(tmp_path / "out")])
    assert alone.exit_code == 0, alone.output


def test_scheduler_without_dask_is_one_line(shoot, monkeypatch):
    folder, config, captures = shoot
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if not installed
    result = CliRunner().invoke(cli, ["batch", str(config), "--inputs", str(captures[0]),
                                      "--out", str(folder / "nodask"),
                                      "--scheduler", "tcp://127.0.0.1:1"])
    assert result.exit_code == 1
    assert result.stderr.strip().splitlines()[-1] == (
        "Error: --scheduler needs dask.distributed, which is not installed; install it with: "
        "pip install 'plenocli[dask]'")


# ----------------------------------------------------------------------------------- Ctrl-C

# Loaded by every interpreter of the batch (parent, fork server, workers) through PYTHONPATH:
# each per-capture bias output is written in full to its temporary file, then held there (a
# marker file says so) until the worker is stopped. Ctrl-C then always lands mid-write, with
# no capture able to finish: no timing involved.
HOLD_BIASED_WRITES = """\
import contextlib, os, time
from pathlib import Path

import plenocli.io.tiffio as tiffio

_write = tiffio.atomic_path


@contextlib.contextmanager
def _held(path, **kwargs):
    with _write(path, **kwargs) as tmp:
        yield tmp
        if Path(path).name == "biased.tif":
            Path(os.environ["PLENOCLI_TEST_MARKERS"], Path(path).parent.name).touch()
            while True:
                time.sleep(3600)  # until SIGTERM stops the worker


tiffio.atomic_path = _held
"""


def test_ctrl_c_leaves_no_partial_output(tmp_path):
    config, captures = make_shoot(tmp_path, 4, corrupt=None)
    out, hook, markers = tmp_path / "out", tmp_path / "hook", tmp_path / "markers"
    hook.mkdir()
    markers.mkdir()
    (hook / "sitecustomize.py").write_text(HOLD_BIASED_WRITES)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(hook), str(ROOT)]),
           "PLENOCLI_TEST_MARKERS": str(markers)}
    proc = subprocess.Popen([sys.executable, "-m", "plenocli", "batch", str(config), "--inputs",
                             str(tmp_path / "captures" / "*.dng"), "-j", "2", "--out", str(out)],
                            env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not any(markers.iterdir()):  # a worker holds a written biased.tif.part
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "no capture reached bias"
            time.sleep(0.05)
        held = list(out.rglob(".biased.tif.*.part"))
        assert held and held[0].stat().st_size > 0  # the interrupt lands mid-write
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "interrupted; no partial output was kept" in stderr
    assert not list(out.rglob("*.part")), "a temporary file was left behind"
    for tif in out.rglob("*.tif"):
        pixels(tif)  # every file present is complete
    assert not list(out.rglob("biased.tif")) and not list(out.rglob("views.tif"))


# ------------------------------------------------------- crashes, time limits, dying parents

def _fake_capture(config, capture, **kwargs):
    """Stands in for run_capture in forked workers: the capture's name says what it does."""
    import plenocli.pipeline.batch as batch_mod

    name = Path(capture).stem
    if name == "crash":
        os._exit(3)
    if name == "slow":
        time.sleep(60)
    if name == "stuck":  # a stage that swallows every interruption (stuck in compiled code)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                time.sleep(60)
            except BaseException:
                pass
    return batch_mod.CaptureResult(capture, name, "done", "ok")


@pytest.fixture
def forked_pool(monkeypatch):
    """Workers forked from this process, so that they see the patched run_capture."""
    import multiprocessing

    import plenocli.pipeline.batch as batch_mod

    monkeypatch.setattr(batch_mod, "_context", lambda: multiprocessing.get_context("fork"))
    monkeypatch.setattr(batch_mod, "run_capture", _fake_capture)
    monkeypatch.setattr(batch_mod, "GRACE_SECONDS", 0.5)
    return batch_mod


def test_crash_and_time_limit_fail_their_capture_only(forked_pool):
    captures = ["/x/crash.dng", "/x/slow.dng", "/x/fine.dng", "/x/stuck.dng"]
    start = time.monotonic()
    results = {r.name: r for r in forked_pool._pool_results(2, "cfg", captures, {}, 0.5)}
    assert time.monotonic() - start < 20
    assert results["fine"].status == "done"
    assert results["crash"].status == "failed" and "died" in results["crash"].detail
    for name in ("slow", "stuck"):
        assert results[name].status == "failed", results[name]
        assert "ran past --timeout 0.5 s" in results[name].detail


def test_interrupt_between_results_stops_the_workers(forked_pool, monkeypatch):
    import multiprocessing

    def interrupted_after_first(items, label, total=None):
        yield next(iter(items))
        raise KeyboardInterrupt

    monkeypatch.setattr(forked_pool, "progress", interrupted_after_first)
    results = forked_pool._pool_results(2, "cfg", ["/x/fine.dng", "/x/slow.dng"], {}, None)
    with pytest.raises(KeyboardInterrupt):
        forked_pool._collect(results, 2)
    assert not multiprocessing.active_children()  # "slow" would sleep on for a minute


def test_second_interrupt_while_stopping_kills_the_workers(forked_pool, monkeypatch):
    import multiprocessing
    from types import SimpleNamespace

    def interrupted(sentinels, timeout):   # Ctrl-C again while the workers are given time
        raise KeyboardInterrupt

    results = forked_pool._pool_results(2, "cfg", ["/x/fine.dng", "/x/stuck.dng"], {}, None)
    assert next(results).name == "fine"
    monkeypatch.setattr(forked_pool, "connection", SimpleNamespace(wait=interrupted))
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        results.close()
    assert time.monotonic() - start < 5   # "stuck" ignores SIGTERM: killed, not waited for
    assert not multiprocessing.active_children()


def test_timeout_must_be_positive(shoot):
    _, config, captures = shoot
    with pytest.raises(ConfigError, match="--timeout"):
        run_batch(config, captures[:1], timeout=float("nan"))


def _group_gone(pgid: int, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.1)
    return False


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGKILL, -9)])
def test_batch_parent_death_takes_its_workers(tmp_path, sig, code):
    config, captures = make_shoot(tmp_path, 4, corrupt=None, rows=600, cols=800)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "plenocli", "batch", str(config), "--inputs",
                             str(tmp_path / "captures" / "*.dng"), "-j", "2", "--out", str(out)],
                            env=env, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while not list(out.glob("shot*/frames.tif")) and time.monotonic() < deadline:
            time.sleep(0.02)  # the workers are busy with captures
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=30)  # a lingering worker would hold the pipe
        assert proc.returncode == code, stderr
        if sig == signal.SIGTERM:
            assert stderr.strip().splitlines()[-1] == (
                "plenocli: terminated; no partial output was kept")
        assert _group_gone(proc.pid, 15), "a worker, the fork server or the tracker lingers"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    assert not list(out.rglob("*.part")), "a temporary file was left behind"
    for tif in out.rglob("*.tif"):
        pixels(tif)  # every file present is complete


def test_captures_within_the_time_limit_are_done(shoot, tmp_path):
    _, config, captures = shoot
    fine = [c for c in captures if c.stem != CORRUPT][:2]
    report = run_batch(config, fine, out=tmp_path / "out", jobs=1, timeout=120)
    assert [r.status for r in report.results] == ["done", "done"]
    assert not list((tmp_path / "out").rglob("*.part"))


def test_one_terminated_and_one_sigterm_handler_for_every_command():
    """SIGTERM is turned into one exception, by one handler at the command edge (a batch
    included); only a batch worker process has its own (issue 18)."""
    import re

    from plenocli.errors import Terminated

    package = ROOT / "plenocli"
    sources = {p: p.read_text() for p in package.rglob("*.py")}
    classes = [p for p, text in sources.items() if re.search(r"^class Terminated\b", text, re.M)]
    handlers = sorted(f"{p.relative_to(package).as_posix()}:{m}" for p, text in sources.items()
                      for m in re.findall(r"def (\w+)\(signum, frame\)", text))
    assert classes == [package / "errors.py"]
    assert handlers == ["cli/options.py:handler",           # the edge of every command
                        "pipeline/batch.py:_on_alarm",      # a worker's time limit
                        "pipeline/batch.py:_on_sigterm"]    # a worker's SIGTERM
    assert issubclass(Terminated, KeyboardInterrupt)  # every Ctrl-C clean-up applies


@pytest.mark.parametrize("pattern", ["", "{d}", "{d}/", "@{d}/list.txt"])
def test_inputs_that_name_a_folder_or_nothing_are_usage_errors(tmp_path, pattern):
    # own-8 (round 10): --inputs FOLDER (or '') reached the config's decode step, which blamed
    # the config: "batch.yaml: step 'decode': Invalid value for 'INPUT': ... is a directory"
    from plenocli.errors import OptionError

    shoot = tmp_path / "shoot"
    shoot.mkdir()
    (shoot / "list.txt").write_text(f"{shoot}\n")
    with pytest.raises(OptionError, match="the pattern is empty" if not pattern else
                       f"{shoot} is a folder, not a capture"):
        expand_inputs([pattern.format(d=shoot)])


def test_a_batch_waits_for_another_writing_its_shared_steps(tmp_path):
    # audit 10 P2, for batch: two batches of one shoot ran the shared steps at once, each
    # reading a white file the other then replaced; the shared steps hold the run's lock
    import fcntl
    import subprocess
    import sys
    import time

    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    (tmp_path / "out").mkdir()
    fd = os.open(tmp_path / "out", os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)   # another batch, running the shared steps
    try:
        batch = subprocess.Popen(
            [sys.executable, "-c", "from plenocli.cli.main import cli; cli()", "batch",
             str(config), "--inputs", str(captures[0]), "-j", "1"], cwd=tmp_path,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(4)
        assert batch.poll() is None and not (tmp_path / "out" / "white_frames.tif").exists()
    finally:
        os.close(fd)
    _, err = batch.communicate(timeout=120)
    assert batch.returncode == 0, err
    assert "waiting for another run writing into" in err


def test_the_summary_shows_a_name_that_is_not_utf8_as_a_terminal_does():
    """audit 25 M: a capture named with a byte that is not UTF-8 was printed as Python's
    surrogate escape, its columns out of line."""
    from plenocli.pipeline.batch import BatchReport, CaptureResult

    name = os.fsdecode(b"c\xffd")
    report = BatchReport([], [CaptureResult("c.dng", name, "done", "", 1.0),
                              CaptureResult("e.dng", "efg", "done", "", 1.0)])
    lines = format_summary(report).splitlines()
    assert lines[1].startswith("c\ufffdd ") and lines[1].index("done") == lines[2].index("done")
