"""Helpers shared by the benchmarks: timing, JSON lines, environment record (../shared/BENCH.md)."""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys

from chronocl.core.budget import peak_resident_bytes
from chronocl.core.timing import race  # noqa: F401  (the benchmarks import it from here)


def reset_peak_rss() -> bool:
    """Reset the kernel's RSS high-water mark (VmHWM) of this process; False where not allowed."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_rss() -> int | None:
    """This process's peak RSS (VmHWM) in bytes, None where /proc has none."""
    return peak_resident_bytes()


def emit(obj: dict) -> None:
    print(json.dumps(obj), flush=True)


def env_record(bench: str, extra: dict | None = None) -> dict:
    import numpy as np

    record = {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
    }
    try:
        import pyopencl as cl

        from chronocl.engine.device import get_context

        dc = get_context()
        record.update(
            pyopencl=cl.VERSION_TEXT,
            platform=dc.info.platform,
            device=dc.info.name,
            driver=dc.info.driver,
            device_version=dc.info.version,
        )
    except Exception as exc:  # the env line must print even without OpenCL
        record["opencl"] = f"unavailable: {exc}"
    record.update(extra or {})
    return {"bench": bench, "env": record}


def volume_args(doc: str):
    """Parse the options of a benchmark over a cube of generated steps: --quick (128^3, 3
    repeats; else 256^3, 5), --size, --steps, --repeats. Returns (args, shape, repeats)."""
    import argparse

    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="128^3 and 3 repeats")
    parser.add_argument("--size", type=int, default=None, help="edge of the cubic volume")
    parser.add_argument("--steps", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=None)
    args = parser.parse_args()
    n = args.size or (128 if args.quick else 256)
    return args, (n, n, n), args.repeats or (3 if args.quick else 5)


def percentiles(ms: list[float], digits: int = 1) -> dict:
    """The count, p50, p95 and max of times in ms (the p95: the sample nearest 95 % up),
    rounded to `digits` decimals."""
    if not ms:
        return {"n": 0}
    ordered = sorted(ms)
    p95 = ordered[min(len(ordered) - 1, round(0.95 * (len(ordered) - 1)))]
    return {
        "n": len(ms),
        "p50": round(statistics.median(ordered), digits),
        "p95": round(p95, digits),
        "max": round(ordered[-1], digits),
    }
