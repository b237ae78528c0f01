"""plenocli.warmup: the install-time numba warm-up runs and names what it warmed."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import plenocli
from plenocli import warmup


def test_warmup_runs_every_warmer(capsys):
    warmup.main()
    out = capsys.readouterr().out
    for name in warmup.WARMERS:
        assert f"plenocli warm-up: {name} kernels ready" in out


# ------------------- a read-only install: numba caches elsewhere, or not at all

NUMBA_MODULES = ("plenocli.refocus", "plenocli.unmix")  # the others are cached alike
CHILD = """
import sys, tempfile
tempfile.tempdir = sys.argv[2]
sys.path.insert(0, sys.argv[1])
import importlib, os
for name in {modules}:
    importlib.import_module(name)
from plenocli import probe
assert probe.add(2, 3) == 5
print("cache:", os.environ.get("NUMBA_CACHE_DIR"))
"""
PROBE = "import numba\n\n\n@numba.njit(cache=True)\ndef add(a, b):\n    return a + b\n"


def _read_only_install(tmp_path: Path) -> Path:
    """A copy of the package where nothing can be written beside the sources (each
    __pycache__ is a file), for root too, who may write a folder whatever its mode."""
    site = tmp_path / "site"
    shutil.copytree(Path(plenocli.__file__).parent, site / "plenocli",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (site / "plenocli" / "probe.py").write_text(PROBE)
    for init in (site / "plenocli").rglob("__init__.py"):
        (init.parent / "__pycache__").write_text("not a folder")
    return site


def _run_child(site: Path, home: Path, temp: Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("NUMBA_") and k != "XDG_CACHE_HOME"}
    env.update(HOME=str(home), PYTHONDONTWRITEBYTECODE="1")
    code = CHILD.format(modules=NUMBA_MODULES)
    return subprocess.run([sys.executable, "-c", code, str(site), str(temp)], env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("temp_writable", [True, False])
def test_kernels_work_on_a_read_only_install_with_home_unwritable(tmp_path, temp_writable):
    site = _read_only_install(tmp_path)
    blocked = tmp_path / "a-file"
    blocked.write_text("")  # HOME (and the temp folder) below a file: nothing can be created
    temp = tmp_path / "tmp" if temp_writable else blocked / "tmp"
    if temp_writable:
        temp.mkdir()
    result = _run_child(site, blocked / "home", temp)
    assert result.returncode == 0, result.stderr[-2000:]
    cache = result.stdout.strip().rsplit("cache: ", 1)[-1]
    if temp_writable:
        folder = temp / f"plenocli-numba-{os.getuid()}"
        assert cache == str(folder)
        assert (folder.stat().st_mode & 0o777) == 0o700
        assert any(folder.rglob("probe.add-*.nbi")), "the kernel was not cached there"
    else:
        assert cache == "None"


def test_the_cache_goes_to_the_first_folder_that_can_be_written(tmp_path):
    from plenocli import numba_cache_dir

    blocked = tmp_path / "a-file"
    blocked.write_text("")
    package = tmp_path / "package"
    package.mkdir()
    assert numba_cache_dir(str(package), {}) is None  # writable: numba's default place
    assert numba_cache_dir(str(blocked), {"NUMBA_CACHE_DIR": str(tmp_path / "mine")}) is None
    user = numba_cache_dir(str(blocked), {"NUMBA_CACHE_DIR": str(blocked / "x"),
                                          "XDG_CACHE_HOME": str(tmp_path / "c")})
    assert user == str(tmp_path / "c" / "plenocli" / "numba")
