"""decode + bias + flat of a full-size 6880 x 4544 two-frame dual-pixel capture.

Baseline, measured in the same run: a bare rawpy (LibRaw) unpack of the same file's frames
(shot 0 and shot 1, copied out of LibRaw), i.e. the least any decoder must do. Prints times, the
ratio to the baseline (target <= 3) and the peak resident memory (target < 2 GB).

    python bench/bench_dualpixel.py [--rows 4480 --cols 6720]
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import rawpy

from plenocli.bias import subtract_overscan
from plenocli.dualpixel import split_views
from plenocli.flatfield import apply_gain, white_gain
from plenocli.io.dng import write_dng
from plenocli.io.raw import decode
from plenocli.synth.dualpixel import dng_options, dualpixel_capture


def best_of(n, func):
    times = []
    for _ in range(n):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return min(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=4502)  # 4544 - 42 over-scan rows
    parser.add_argument("--cols", type=int, default=6744)  # 6880 - 136 over-scan columns
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "capture.dng"
        raw, truth = dualpixel_capture(seed=0, rows=args.rows, cols=args.cols, top=42, left=136)
        write_dng(path, raw, **dng_options(truth))
        _, wtruth = dualpixel_capture(seed=1, rows=args.rows, cols=args.cols, top=42, left=136,
                                      scene="white")
        del raw
        gains = np.stack([white_gain(wtruth[v], cfa="RGGB") for v in ("A", "B", "S")])
        del wtruth, truth
        geo_active, geo_masked = [42, 136, 42 + args.rows, 136 + args.cols], \
            [[0, 0, 42 + args.rows, 136], [0, 136, 42, 136 + args.cols]]

        def baseline():
            for shot in (0, 1):
                with rawpy.imread(str(path), shot_select=shot) as r:
                    r.raw_image.copy()

        def pipeline():
            frames, meta = decode(path)
            out, clipped = [], []
            for k in range(2):
                corrected, _ = subtract_overscan(frames[k], active_area=geo_active,
                                                 masked_areas=geo_masked, smooth=9)
                clipped.append(frames[k, 42:, 136:] >= meta["white_level"][k])
                out.append(corrected)
            views = split_views(out[0], out[1], sum_clipped=clipped[0], a_clipped=clipped[1])
            return [apply_gain(v, g) for v, g in zip(views, gains, strict=True)]

        t_base = best_of(args.repeat, baseline)
        t_pipe = best_of(args.repeat, pipeline)
        start = time.perf_counter()
        white_gain(gains[0], cfa="RGGB")  # the gain of one view, made once per session
        t_gain = time.perf_counter() - start
        tracemalloc.start()  # numpy reports its buffers to tracemalloc
        pipeline()
        peak_gb = tracemalloc.get_traced_memory()[1] / 1024**3
        tracemalloc.stop()
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024**2
    print(f"frame {args.rows + 42} x {args.cols + 136}, two frames")
    print(f"baseline rawpy unpack of 2 frames : {t_base:.3f} s")
    print(f"decode + bias + split + flat      : {t_pipe:.3f} s")
    print(f"ratio                             : {t_pipe / t_base:.2f}  (target <= 3)")
    print(f"white gain of one view (once)     : {t_gain:.3f} s")
    print(f"peak memory of the pipeline       : {peak_gb:.2f} GB (target < 2)")
    print(f"peak resident, whole script       : {rss_gb:.2f} GB (includes making the fixture)")


if __name__ == "__main__":
    main()
