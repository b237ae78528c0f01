"""Batch throughput: captures per minute with 1 and 2 worker processes on this machine.

    python bench/bench_batch.py [--captures 16] [--size 4480x6720]

Writes synthetic dual-pixel captures (plenocli.synth.dualpixel) and a white image into a temporary
folder, runs the batch template of tests/test_batch.py (decode -> bias -> flat, white shared) with
`plenocli batch --jobs 1` and `--jobs 2`, each as a fresh command (the shared white-image steps
done beforehand), and prints the throughput and the speed-up.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from plenocli.pipeline.batch import run_batch  # noqa: E402
from tests.test_batch import make_shoot  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--captures", type=int, default=16)
    parser.add_argument("--size", default="4480x6720", help="active area ROWSxCOLS")
    parser.add_argument("--tmp", default=None, help="work folder (default: the system's temp)")
    args = parser.parse_args()
    rows, cols = (int(v) for v in args.size.split("x"))
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        config, captures = make_shoot(folder, 1, corrupt=None, rows=rows, cols=cols,
                                      top=42, left=136)
        for k in range(1, args.captures):  # copies: the work per capture is what counts
            copy = captures[0].with_name(f"shot{k:02d}.dng")
            copy.write_bytes(captures[0].read_bytes())
            captures.append(copy)
        print(f"{args.captures} dual-pixel captures of {rows} x {cols} (+ over-scan), written in "
              f"{time.perf_counter() - start:.1f} s")
        run_batch(config, captures[:1], out=folder / "warm", jobs=1)  # shared steps, imports
        rates = {}
        for jobs in (1, 2):
            out = folder / f"jobs{jobs}"
            # the shared steps' outputs (white image, gain: the top level of the warm-up folder)
            # are copied in, so both runs time only the per-capture work
            out.mkdir(exist_ok=True)
            for shared in (folder / "warm").iterdir():  # with their records, times kept
                if shared.is_file():
                    shutil.copy2(shared, out / shared.name)
            os.sync()  # the files just written are flushed first, not during the timed run
            load = os.getloadavg()[0]
            # each run is the whole command in a fresh process, as a user runs it
            command = [sys.executable, "-m", "plenocli", "batch", str(config), "--inputs",
                       str(captures[0].parent / "*.dng"), "--out", str(out), "-j", str(jobs),
                       "-q"]
            start = time.perf_counter()
            done = subprocess.run(command, capture_output=True, text=True,
                                  env={**os.environ, "PYTHONPATH": str(ROOT)})
            seconds = time.perf_counter() - start
            if done.returncode != 0:
                raise SystemExit(f"batch --jobs {jobs} failed: {done.stderr.strip()}")
            rates[jobs] = 60.0 * len(captures) / seconds
            print(f"--jobs {jobs}: {seconds:6.1f} s  {rates[jobs]:6.1f} captures/min  "
                  f"(whole command; load average before {load:.1f})")
        print(f"speed-up 2 jobs / 1 job: {rates[2] / rates[1]:.2f}x (target >= 1.7x)")
        child = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        print(f"largest peak resident memory of a batch process: {child:.0f} MB")


if __name__ == "__main__":
    main()
