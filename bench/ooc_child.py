"""The fresh process of bench/out_of_core.py: integrate a store under a budget, report RSS.

    python bench/ooc_child.py STORE OUT BUDGET MODE COMPRESSOR   # prints one JSON line

Its baseline is its RSS after importing chronocl, creating the OpenCL context and building
the kernels; its peak the kernel's high-water mark (VmHWM, reset before the run), or an RSS
sampled every 2 ms where that cannot be reset.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import numpy as np
from common import peak_rss, reset_peak_rss

from chronocl.data.series import open_series


def _rss() -> int:
    import psutil

    return psutil.Process().memory_info().rss


def child(store: str, out: str, budget: int, mode: str, compressor: str) -> None:
    import gc

    import chronocl
    from chronocl.engine import get_engine
    from chronocl.integration.inmemory import engine_rows, prepare
    from chronocl.integration.runs.plan import plan_slabs
    from chronocl.integration.runs.streaming import integrate_to_store

    series = open_series(store)
    _, ny, nx = series.volume_shape
    warm = np.random.default_rng(0).random((2, 2, ny, nx), dtype=np.float32)
    chronocl.integrate(chronocl.TimeSeries.from_array(warm), None, mode)  # context, kernels
    job = prepare(series, None, mode, None, {})
    plan = plan_slabs(job, budget, "opencl", engine_rows(get_engine("opencl"), job))
    del warm
    gc.collect()
    baseline = _rss()
    sampled = [baseline]
    stop = threading.Event()

    def sample() -> None:  # a cross-check where VmHWM cannot be reset
        while not stop.wait(0.002):
            sampled.append(_rss())

    hwm_ok = reset_peak_rss()
    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    t0 = time.perf_counter()
    integrate_to_store(
        series, None, out, mode=mode, memory=budget, overwrite=True, compressor=compressor
    )
    seconds = time.perf_counter() - t0
    stop.set()
    sampler.join()
    hwm = peak_rss() if hwm_ok else None
    peak = max(hwm or 0, max(sampled))
    print(
        json.dumps(
            {
                "seconds": seconds,
                "baseline_rss": baseline,
                "peak_rss": peak,
                "peak_method": "VmHWM reset before the run" if hwm_ok else "sampled every 2 ms",
                "sampled_peak_rss": max(sampled),
                "slabs": len(plan.slabs),
                "slab_rows": plan.slab_rows,
                "read_ahead": plan.read_ahead,
                "steps_per_read": plan.steps_per_read,
                "estimated_peak": plan.peak_bytes,
            }
        )
    )


def run_child(*args: object) -> dict:
    result = subprocess.run(
        [sys.executable, __file__, *map(str, args)],
        capture_output=True,
        text=True,
        check=False,
    )
    if result.returncode != 0:
        raise RuntimeError(result.stderr)
    return json.loads(result.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    store, out, budget, mode, compressor = sys.argv[1:6]
    child(store, out, int(budget), mode, compressor)
