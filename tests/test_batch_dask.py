"""The Dask engine on a real LocalCluster (worker processes on this machine)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from click.testing import CliRunner

from plenocli.cli.main import cli
from plenocli.pipeline.batch import run_batch
from tests.test_batch import make_shoot, pixels

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  host="127.0.0.1", dashboard_address=None) as local:
        yield local


def test_dask_gives_the_local_outputs(tmp_path, cluster):
    config, captures = make_shoot(tmp_path, 6, corrupt="shot03")
    local = run_batch(config, captures, out=tmp_path / "local", jobs=2)
    args = ["batch", str(config), "--inputs", str(tmp_path / "captures" / "*.dng"),
            "--out", str(tmp_path / "dask"), "--scheduler", cluster.scheduler_address]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 1  # shot03 is truncated
    failures = [ln for ln in result.stderr.splitlines() if ln.startswith("failed: ")]
    assert len(failures) == 1 and "shot03.dng: step 'decode'" in failures[0]
    assert [r.status for r in local.results] == ["done"] * 3 + ["failed"] + ["done"] * 2
    for c in captures:
        if c.stem == "shot03":
            continue
        for name in ("frames.tif", "biased.tif", "views.tif"):
            np.testing.assert_array_equal(pixels(tmp_path / "dask" / c.stem / name),
                                          pixels(tmp_path / "local" / c.stem / name))
    again = run_batch(config, captures, out=tmp_path / "dask",
                      scheduler=cluster.scheduler_address)
    assert [r.status for r in again.results if r.name != "shot03"] == ["skipped"] * 5


def test_unreachable_scheduler_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr("plenocli.pipeline.batch.DASK_CONNECT_TIMEOUT", "2s")
    config, captures = make_shoot(tmp_path, 1, corrupt=None)
    result = CliRunner().invoke(cli, ["batch", str(config), "--inputs", str(captures[0]),
                                      "--out", str(tmp_path / "o"),
                                      "--scheduler", "tcp://127.0.0.1:9"])
    assert result.exit_code == 1
    assert "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in result.stderr


def test_relative_paths_are_resolved_where_the_batch_runs(tmp_path, cluster, monkeypatch):
    """Workers run in their own folder: the config, captures and --out given relative to the
    batch's folder must reach them as absolute paths (issue 21, class 9)."""
    config, captures = make_shoot(tmp_path / "project", 3, corrupt=None)
    local = run_batch(config, captures, out=tmp_path / "local", jobs=1)
    assert [r.status for r in local.results] == ["done"] * 3
    monkeypatch.chdir(tmp_path / "project")
    with distributed.Client(cluster, set_as_default=False) as client:
        folders = set(client.run(os.getcwd).values())
    assert folders and str(tmp_path / "project") not in folders
    args = ["batch", "batch.yaml", "--inputs", "captures/*.dng", "--out", "../dask",
            "--scheduler", cluster.scheduler_address]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    for c in captures:
        for name in ("frames.tif", "biased.tif", "views.tif"):
            np.testing.assert_array_equal(pixels(tmp_path / "dask" / c.stem / name),
                                          pixels(tmp_path / "local" / c.stem / name))


def test_an_interruption_names_the_captures_the_cluster_still_runs(tmp_path, cluster,
                                                                   monkeypatch):
    """audit 22c M1: Dask cannot stop a running task; the command said "no partial output was
    kept" and exited while the workers went on writing those captures' outputs."""
    import time

    config, captures = make_shoot(tmp_path, 4, corrupt=None)

    def interrupted(futures, *args, **kwargs):  # Ctrl-C while the batch waits for results
        with distributed.Client(cluster.scheduler_address, set_as_default=False) as watcher:
            deadline = time.monotonic() + 30
            while not any(watcher.processing().values()) and time.monotonic() < deadline:
                time.sleep(0.005)
        raise KeyboardInterrupt

    monkeypatch.setattr(distributed, "as_completed", interrupted)
    result = CliRunner().invoke(cli, ["batch", str(config), "--inputs",
                                      str(tmp_path / "captures" / "*.dng"), "--out",
                                      str(tmp_path / "o"), "--scheduler",
                                      cluster.scheduler_address])
    assert result.exit_code == 130, result.output
    said = result.stderr.strip().splitlines()[-1]
    assert said.startswith("plenocli: interrupted; no partial output was kept; but shot")
    assert "had started on the Dask cluster" in said and "rerun the batch" in said
