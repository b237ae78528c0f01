"""Timing helper shared by the benchmarks (run them as ``PYTHONPATH=. python bench/bench_X.py``)."""

import time


def best_time(func, repeat: int):
    """The best wall time of ``repeat`` calls of ``func`` and the last call's result."""
    times, result = [], None
    for _ in range(repeat):
        start = time.perf_counter()
        result = func()
        times.append(time.perf_counter() - start)
    return min(times), result
