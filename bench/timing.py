"""Timing helper shared by the benchmarks (run them as ``PYTHONPATH=. python bench/bench_X.py``)."""

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def best_time(func, repeat: int):
    """The best wall time of ``repeat`` calls of ``func`` and the last call's result."""
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = func()
        times.append(time.perf_counter() - start)
    return min(times), result


def export_package(commit: str, dest: Path) -> Path:
    """The ``plenocli`` package of a git commit of this repository, unpacked into ``dest``
    (to be put on PYTHONPATH: a baseline run by the same benchmark)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit, "plenocli"],
                             capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    return dest


def run_python(code: str, *args: str, root: Path) -> str:
    """The standard output of ``code`` run by this Python with ``root`` first on its path (a
    failure raises with the child's error output, not only its exit status)."""
    run = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         cwd=root, env={**os.environ, "PYTHONPATH": str(root)})
    if run.returncode:
        raise RuntimeError(f"the run under {root} failed:\n{run.stderr}")
    return run.stdout
