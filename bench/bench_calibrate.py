"""Benchmark: calibration of 2048 x 2048 and 6720 x 4480 synthetic white images (in memory), and
the whole `plenocli calibrate` command with file reading. Prints times and peak memory."""

from __future__ import annotations

import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import tifffile
import yaml

from plenocli import hexgrid
from plenocli.io import gridfile
from plenocli.synth.whiteimage import white_image


def main() -> None:
    hexgrid.calibrate(white_image((256, 256), pitch_px=12.0, angle_rad=0.1,
                                  offset_xy=(128, 128))[0])  # compile numba
    for rows, cols, target in ((2048, 2048, 0.5), (4480, 6720, 1.5)):
        image, _ = white_image((rows, cols), pitch_px=20.2, angle_rad=0.05,
                               offset_xy=(cols / 2 + 0.3, rows / 2 + 0.6), cfa="RGGB", seed=1)
        times = []
        for _ in range(3):
            t = time.perf_counter()
            grid, _ = hexgrid.calibrate(image, cfa="RGGB", black_level=64)
            times.append(time.perf_counter() - t)
        best = min(times)
        tracemalloc.start()
        hexgrid.calibrate(image, cfa="RGGB", black_level=64)
        peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
        print(f"calibrate {cols}x{rows}: {best:.3f} s (target {target} s, ratio "
              f"{best / target:.2f}), pitch {grid.pitch_px:.5f}; peak traced memory "
              f"{peak_mb:.0f} MB = {peak_mb / (image.size * 4 / 1e6):.1f} x the float32 image")
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / "white.tif"
            tifffile.imwrite(src, image)
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "plenocli", "calibrate", str(src), "-o",
                            str(Path(tmp) / "g.yaml"), "-q"], check=True)
            print(f"  whole command with file reading: {time.perf_counter() - t:.2f} s")
            gpath = Path(tmp) / "g.yaml"
            t = time.perf_counter()
            read = gridfile.read_grid(gpath)
            fast = time.perf_counter() - t
            t = time.perf_counter()
            yaml.load(gpath.read_text(), Loader=gridfile._LOADER)
            plain = time.perf_counter() - t
            print(f"  read_grid of {len(read.centres_xy)} lenses: {fast:.3f} s (target 0.3 s); "
                  f"whole file through libyaml {plain:.2f} s ({plain / fast:.0f} x)")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS of this process {peak:.0f} MB (dominated by the synthetic image "
          f"generator; calibrate's own peak is the traced figure above); numpy {np.__version__}")


if __name__ == "__main__":
    main()
