"""Events through time at users' sizes: `chronocl.events` over a window, its time split into
the steps' reads, their labelling (mask, connected components, measures), the matching of
consecutive steps and the tracks and graph, against the read bound: the same steps read from
the same store with every core reading (one step per thread, decoded, nothing else done).
Peak RSS is the run's own (a fresh process, VmHWM reset before each run) against the budget
`find` plans its steps in flight for (`chronocl.events.run.memory_budget`).

    python bench/events.py                        # 512^3 x 20 float32 vortex, 3 repeats
    python bench/events.py --quick                # 128^3 x 20, 3 repeats; well under 2 minutes
    python bench/events.py --store v512.zarr      # an existing store (its first 20 steps)

Generated stores are written under the system's temporary folder and removed afterwards
(keep one with --keep DIR). Issue 51's target: 512^3 x 20 events in <= 30 s, peak RSS within
the budget. Prints JSON lines: env, one line per repeat, the summary.

Labelling on threads (before issue 51's worker processes; 2 cores, shared with other work,
load 2-3, 2026-11-30; the vortex at threshold 0.3, 64 features, the store in the page cache):
512^3 x 20 in 12.0 s (median of 3; 9.7-12.2) against a read bound of 0.9 s; per step,
thread-summed, read 184 ms, labelling 948 ms, matching 67 ms; peak RSS 3.1 GB of an 11.8 GB
budget (0.27). connected-components-3d holds the GIL while it labels, so two threads gain
nothing over one (CHRONOCL_THREADS=1: 11.3 s, min 8.9, labelling 476 ms a step, peak 1.9 GB).
Before the shown voxels were measured and matched by their indices and the read and mask
buffers used again it took 55 s (load 6-9): labelling 2.9 s, matching 1.6 s a step.

On worker processes (`chronocl.events.processes`: a window of 1.5e9 voxels or more from a
store; same host, load about 4, 2026-11-30, back to back): 12.35 s (median of 3; 11.7-12.8)
against 14.0 s (9.2-21.6) on threads; per step, worker-summed, read 138 ms, labelling with
the overlaps 834 ms, matching 10 ms on the calling process (which now only turns overlap
counts into edges); peak RSS 148 MB here plus 2.76 GB over both workers (their peaks summed).
One find per fresh process, 20 steps, 5 of each interleaved: threads (2) median 15.4 s (min
7.5), processes (2) 11.3 s (min 6.6), threads (1) 13.6 s (min 10.0); CPU (user + sys) about
12-14.6 s for the processes against 9-11 s for one thread: the two workers' start (imports,
buffers) costs about 1.7 s, which is why short windows stay on threads. --quick (128^3) labels
on threads as before: 0.15 s.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import emit, env_record, peak_rss, reset_peak_rss

TARGET_S = 30.0
THRESHOLD = 0.3


def child(store: str, window: str, threshold: float, repeats: int) -> None:
    """Measure in this fresh process: one JSON line per repeat (read bound, then events)."""
    from concurrent.futures import ThreadPoolExecutor

    import numpy as np
    import psutil

    import chronocl
    from chronocl.core.host_threads import workers
    from chronocl.events.run import Timings, find, memory_budget, prepare

    series = chronocl.open(store)
    chronocl.events(np.zeros((2, 4, 4, 4), np.float32), threshold=1.0)  # imports cc3d, networkx
    job = prepare(series, window, threshold=threshold)
    steps = job.selection.steps

    mine = threading.local()  # a buffer per thread, used again as `find` uses its buffers
    brick = (series.volume_shape[0], 1, *series.volume_shape[1:])

    def read(step: int) -> None:
        if not hasattr(mine, "out"):
            mine.out = np.empty(brick, series.dtype)
        series.read_brick([step], out=mine.out, per_call=1)

    def read_all() -> float:
        t0 = time.perf_counter()
        with ThreadPoolExecutor(workers()) as pool:
            list(pool.map(read, steps))
        return time.perf_counter() - t0

    read_all()  # warm-up: the store's chunks into the page cache, as the events run finds them
    for repeat in range(repeats):
        read_s = read_all()
        baseline = psutil.Process().memory_info().rss
        reset = reset_peak_rss()
        spent = Timings()
        graph = find(job, timings=spent)
        peak = peak_rss() if reset else None
        print(
            json.dumps(
                {
                    "repeat": repeat,
                    "read_bound_s": read_s,
                    "events_s": spent.total_s,
                    "read_s": spent.read_s,
                    "label_s": spent.label_s,
                    "match_s": spent.match_s,
                    "wait_s": spent.wait_s,
                    "tracks_s": spent.tracks_s,
                    "baseline_rss": baseline,
                    "peak_rss": peak,
                    "budget": memory_budget(),
                    "threads": workers(),
                    "processes": spent.processes,
                    "worker_peak_rss": spent.worker_peak_rss,
                    "features": len(graph.features),
                    "events": len([e for e in graph.events if e["kind"] != "continuation"]),
                }
            ),
            flush=True,
        )


def generate(path: Path, size: int, steps: int) -> None:
    import numpy as np

    from chronocl.data import synthetic
    from chronocl.data.series import write_series

    shape = (size, size, size)
    write_series(
        path,
        (np.ascontiguousarray(s) for s in synthetic.steps("vortex", steps, shape, 0)),
        n_steps=steps,
        volume_shape=shape,
        dtype="float32",
        overwrite=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="128^3 x 20, 3 repeats")
    parser.add_argument("--size", type=int, default=None, help="edge of the generated cube")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--store", default=None, help="an existing store to read instead")
    parser.add_argument("--threshold", type=float, default=THRESHOLD)
    parser.add_argument("--keep", default=None, help="write the generated store here, keep it")
    parser.add_argument("--child", nargs=4, metavar=("STORE", "WINDOW", "THRESHOLD", "REPEATS"))
    args = parser.parse_args()
    if args.child:
        store, window, threshold, repeats = args.child
        child(store, window, float(threshold), int(repeats))
        return

    size = args.size or (128 if args.quick else 512)
    tmp = None
    if args.store:
        store = Path(args.store)
    else:
        if args.keep:
            store = Path(args.keep)
        else:
            tmp = Path(tempfile.mkdtemp(prefix="chronocl-bench-events-"))
            store = tmp / "vortex.zarr"
        t0 = time.perf_counter()
        generate(store, size, args.steps)
        emit({"bench": "events", "generated": str(store), "seconds": time.perf_counter() - t0})
    try:
        import chronocl

        series = chronocl.open(store)
        steps = min(args.steps, series.n_steps)
        window = f"0:{steps}"
        z, y, x = series.volume_shape
        case = f"{x}x{y}x{z}xT{steps}-{series.dtype}"
        emit(env_record("events", {"case": case, "store": str(store), "threshold": args.threshold}))
        result = subprocess.run(
            [
                sys.executable,
                __file__,
                "--child",
                str(store),
                window,
                str(args.threshold),
                str(args.repeats),
            ],
            capture_output=True,
            text=True,
            check=False,
        )
        if result.returncode != 0:
            raise SystemExit(result.stderr)
        runs = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
        for run in runs:
            emit({"bench": "events", "case": case, **run})
        summary(case, steps, runs)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def summary(case: str, steps: int, runs: list[dict]) -> None:
    def med(key: str) -> float:
        return statistics.median(r[key] for r in runs)

    total, bound = med("events_s"), med("read_bound_s")
    users_case = case == "512x512x512xT20-float32"
    peaks = [r["peak_rss"] for r in runs if r["peak_rss"] is not None]
    peak = max(peaks) if peaks else None
    budget = runs[0]["budget"]
    emit(
        {
            "bench": "events",
            "summary": {
                "case": case,
                "repeats": len(runs),
                "events_s": round(total, 2),
                "events_min_s": round(min(r["events_s"] for r in runs), 2),
                # issue 51's target is the users' case, 512^3 x 20 float32; none elsewhere
                "target_s": TARGET_S if users_case else None,
                "within_target": total <= TARGET_S if users_case else None,
                "read_bound_s": round(bound, 2),
                "events_over_read": round(total / bound, 2),
                # summed over the threads that did them (read, label) or on the calling thread
                "split_s": {k: round(med(f"{k}_s"), 2) for k in ("read", "label", "match", "wait")}
                | {"tracks_and_graph": round(med("tracks_s"), 3)},
                "per_step_ms": {
                    k: round(1000 * med(f"{k}_s") / steps, 1) for k in ("read", "label", "match")
                },
                "threads": runs[0]["threads"],
                "processes": runs[0]["processes"],  # 0: labelled on threads
                "peak_rss_mb": None if peak is None else round(peak / 1e6),
                # the workers' peaks summed: an upper bound (a label file shared with this
                # process is counted in both); add it to peak_rss_mb for the run's whole
                "workers_peak_rss_mb": round(max(r["worker_peak_rss"] for r in runs) / 1e6),
                "budget_mb": round(budget / 1e6),
                "peak_over_budget": None if peak is None else round(peak / budget, 2),
                "features": runs[0]["features"],
                "events": runs[0]["events"],
            },
        }
    )


if __name__ == "__main__":
    main()
