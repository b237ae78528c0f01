"""Benchmark: start-up of the command line, against a bare Python start in the same run.

Each figure is the median wall time of ``--repeat`` fresh processes (hyperfine-style):
``plenocli --help``, ``plenocli CMD --help`` for every command, and the import overhead of each
command when it runs (its cli module and its stage with every library module the stage loads).
The baseline is ``python -c pass`` with the same interpreter.

    python bench/bench_startup.py [--repeat 7]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

from plenocli.cli.main import COMMANDS

STAGES = ("decode", "bias", "flat", "calibrate", "refocus", "sai", "crosstalk", "stitch",
          "optics")


def median_seconds(args: list[str], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run(args, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    repeat = parser.parse_args().repeat
    py = sys.executable
    base = median_seconds([py, "-c", "pass"], repeat)
    print(f"python -c pass: {base:.3f} s (baseline)")
    rows = [("plenocli --help", [py, "-m", "plenocli", "--help"])]
    rows += [(f"plenocli {name} --help", [py, "-m", "plenocli", name, "--help"])
             for name in COMMANDS]
    rows += [(f"import {name} command and stage",
              [py, "-c", f"import plenocli.cli.{name}, plenocli.pipeline.stages.{name}"])
             for name in STAGES]
    for label, args in rows:
        seconds = median_seconds(args, repeat)
        print(f"{label:<40} {seconds:.3f} s  (+{seconds - base:.3f} s over python, "
              f"{seconds / base:.1f} x)")


if __name__ == "__main__":
    main()
