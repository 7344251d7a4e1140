"""Timing for benchmarks and the scalability report: contenders timed round-robin, medians."""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def race(fns: dict[str, Callable[[], object]], repeats: int, warmup: int = 1) -> dict:
    """Time several contenders round-robin, so machine noise hits them alike.

    Returns {name: (median, minimum)} over `repeats` runs each after `warmup` runs each.
    """
    times = race_times(fns, repeats, warmup)
    return {name: (statistics.median(t), min(t)) for name, t in times.items()}


def race_times(
    fns: dict[str, Callable[[], object]], repeats: int, warmup: int = 1
) -> dict[str, list[float]]:
    """{name: [seconds of each of `repeats` runs]} of contenders run round-robin after
    `warmup` untimed runs each."""
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return times
