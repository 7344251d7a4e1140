"""Distributed integration: the same streamed integration locally and on a 2-worker LocalCluster.

Generates a series in a temporary folder (deleted afterwards), then alternates
`integrate_to_store` in this process (read-ahead, write-behind) and with a `Client` of a
LocalCluster (2 spawned worker processes, 1 thread each; one task per z-slab), after a warm-up
of each. Prints JSON lines (../shared/BENCH.md) and a summary with

- `distributed_over_local`: median wall time distributed / local (target <= 1.3);
- `scheduler_bytes_per_task`: what travels through the scheduler per slab task, measured as
  the pickled task arguments plus the pickled result (target: kilobytes).

    python bench/dask_cluster.py --quick        # 16 x 192^3, 2 repeats; < 2 minutes
    python bench/dask_cluster.py                # 16 x 256^3, 5 repeats
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import emit, env_record, race
from out_of_core import generate

from chronocl.core.budget import parse_memory

# The spawned workers inherit the path: bench/ stays off it from here on (a module of it
# named like one they import would hide that; tests/test_suite_rules.py checks none is).
HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != HERE]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="16 x 192^3, 2 repeats")
    parser.add_argument("--steps", type=int, default=16)
    parser.add_argument("--size", type=int, default=None, help="volume edge N (N^3 voxels)")
    parser.add_argument("--mode", default="alpha")
    parser.add_argument("--memory", default="256MB", help="budget per process / task")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=None)
    args = parser.parse_args()
    size = args.size or (192 if args.quick else 256)
    repeats = args.repeats or (2 if args.quick else 5)
    budget = parse_memory(args.memory)

    import chronocl.integration.runs.distributed as dist
    from chronocl.engine import get_engine
    from chronocl.integration.inmemory import prepare
    from chronocl.integration.runs.streaming import SlabTask, integrate_to_store

    emit(env_record("distributed", {"workers": args.workers, "budget": budget}))
    tmp = Path(tempfile.mkdtemp(prefix="chronocl-dist-"))
    try:
        store = tmp / "series.zarr"
        series = generate(store, args.steps, size, "none", 4.0)
        case = f"T{args.steps}x{size}^3-f32"
        data_bytes = args.steps * size**3 * 4
        get_engine("opencl")

        sizes: list[int] = []

        t0 = time.perf_counter()
        from distributed import Client

        with dist.local_cluster(args.workers) as cluster, Client(cluster) as client:
            startup = time.perf_counter() - t0

            def run(name: str, **kw: object) -> None:
                out = tmp / f"{name}.zarr"
                integrate_to_store(
                    series, None, out, mode=args.mode, memory=budget, overwrite=True, **kw
                )

            def distributed_run() -> None:
                run("dist", client=client)

            # The warm-up builds the kernels in every process.
            times = race({"local": lambda: run("local"), "distributed": distributed_run}, repeats)

            # One more distributed run with the task function spied, to size what travels.
            job = prepare(series, None, args.mode, None, {})
            remote = SlabTask(job, tmp / "x", "0" * 24).remote()
            results: list[dict] = []
            real_run_slabs = dist.DaskExecutor.run_slabs

            def spy(self, task, plan, todo, total):
                out = real_run_slabs(self, task, plan, todo, total)
                results.extend(out)
                return out

            dist.DaskExecutor.run_slabs = spy
            try:
                distributed_run()
            finally:
                dist.DaskExecutor.run_slabs = real_run_slabs
            tasks = len(results)
            call_bytes = len(pickle.dumps((remote, (0, 1, 0, 1))))
            sizes.extend(call_bytes + len(pickle.dumps(info)) for info in results)
        for impl, (med, least) in times.items():
            emit(
                {
                    "bench": "distributed",
                    "case": case,
                    "impl": impl,
                    "mode": args.mode,
                    "median_s": round(med, 3),
                    "min_s": round(least, 3),
                    "repeats": repeats,
                    "value": round(data_bytes / med / 1e9, 3),
                    "unit": "GB/s",
                }
            )
        med_local, med_dist = times["local"][0], times["distributed"][0]
        ratio = med_dist / med_local
        summary = {
            "distributed_over_local": round(ratio, 3),
            "scheduler_bytes_per_task": round(statistics.median(sizes)) if sizes else None,
            "scheduler_bytes_definition": "pickled task arguments + pickled result of one task",
            "tasks_per_run": tasks,
            "workers": args.workers,
            "threads_per_worker": 1,
            "cluster_startup_s": round(startup, 2),
            "local_gb_s": round(data_bytes / med_local / 1e9, 3),
            "distributed_gb_s": round(data_bytes / med_dist / 1e9, 3),
            "data_gb": round(data_bytes / 1e9, 3),
            "budget_mb": round(budget / 1e6),
            "cpu_count": os.cpu_count(),
        }
        emit({"bench": "distributed", "summary": summary})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
