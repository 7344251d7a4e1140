"""The out-of-core bench's breakdown: each stage of the streamed integration alone (read and
decompress, integrate, compress and write), inside the pipeline (`chronocl.integration.runs.
stages`), and the parallel bound they set. Used by bench/out_of_core.py (`--breakdown`).
"""

from __future__ import annotations

import resource
import shutil
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import zarr

from chronocl.integration.runs import stages


def timed(fn) -> tuple[float, float]:
    """(wall seconds, CPU seconds of every thread of this process) of fn()."""
    r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    fn()
    r1, wall = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter() - t0
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def stages_alone(series, out: Path, budget: int, mode: str, compressor: str) -> dict:
    """CPU seconds of the integration's work done alone: kernels on bricks already in memory,
    and writing the output it produced (same chunks and codec) into a new store."""
    from chronocl.data.bricks import SeriesBricks
    from chronocl.data.writer import compressors
    from chronocl.engine import get_engine
    from chronocl.integration.inmemory import engine_rows, integrate_brick, prepare
    from chronocl.integration.runs.plan import plan_slabs

    job = prepare(series, None, mode, None, {})
    eng = get_engine("opencl")
    plan = plan_slabs(job, budget, "opencl", engine_rows(eng, job))
    rows = plan.slab_rows + 2 * job.halo
    bricks = SeriesBricks.buffered(series, rows, job.selection.width, 1, plan.steps_per_read)
    steps = job.selection.steps
    read_wall, read_cpu = timed(lambda: [bricks.read(steps, s.r0, s.r1) for s in plan.slabs])
    kernel_wall = kernel_cpu = 0.0
    for s in plan.slabs:
        brick = bricks.read(steps, s.r0, s.r1)
        w, c = timed(lambda b=brick, s=s: integrate_brick(job, eng, s, b))
        kernel_wall, kernel_cpu = kernel_wall + w, kernel_cpu + c
    src = zarr.open_group(str(out), mode="r")
    dst = zarr.open_group(str(out.with_name("write-alone.zarr")), mode="w", zarr_format=3)
    names = [n for n in ("rgba", "t_index") if n in src]
    for n in names:
        a = src[n]
        dst.create_array(
            n,
            shape=a.shape,
            chunks=a.chunks,
            dtype=a.dtype,
            compressors=compressors(compressor),
            config={"write_empty_chunks": True},
        )
    write_wall = write_cpu = 0.0
    for s in plan.slabs:
        slab = {n: np.asarray(src[n][s.z0 : s.z1]) for n in names}

        def write(slab=slab, s=s) -> None:
            for n in names:
                dst[n][s.z0 : s.z1] = slab[n]

        w, c = timed(write)
        write_wall, write_cpu = write_wall + w, write_cpu + c
    shutil.rmtree(out.with_name("write-alone.zarr"))
    return {
        "read_s": read_wall,
        "read_cpu_s": read_cpu,
        "kernel_s": kernel_wall,
        "kernel_cpu_s": kernel_cpu,
        "write_s": write_wall,
        "write_cpu_s": write_cpu,
    }


def parallel_bound(alone: dict, finish: tuple[float, float], cores: int) -> dict:
    """The least wall time the pipeline can take on `cores`, from its stages measured alone.

    Reads, kernels and writes overlap, but each runs one call at a time (one reader, one
    integrating thread, one writer), so the run takes at least the longest stage's wall time
    alone (its serial share), and at least all their CPU seconds spread over every core. The
    finish (second pass and commit) comes after them. `finish` = (wall, CPU) seconds.
    """
    walls = {k: alone[f"{k}_s"] for k in ("read", "kernel", "write")}
    cpu = sum(alone[f"{k}_cpu_s"] for k in ("read", "kernel", "write"))
    serial = max(walls, key=walls.get)
    overlapped = max(walls[serial], cpu / cores)
    return {
        "bound_s": overlapped + finish[0],
        "limit": f"{serial} stage alone"
        if walls[serial] >= cpu / cores
        else f"CPU / {cores} cores",
        "serial_stage": serial,
        "serial_s": walls[serial],
        "cpu_over_cores_s": cpu / cores,
        "finish_s": finish[0],
    }


def breakdown_table(case: str, alone: dict, pipeline: dict, bound: dict, int_s: float) -> list:
    """One JSON record per stage: CPU and wall seconds alone and inside the pipeline."""
    names = {"read": "read", "kernel": "integrate", "write": "write"}
    records = []
    for key, stage in (*names.items(), ("finish", "finish")):
        inside = pipeline[stage]
        records.append(
            {
                "bench": "out_of_core",
                "case": case,
                "impl": "breakdown",
                "stage": {
                    "read": "read+decompress",
                    "integrate": "integrate",
                    "write": "compress+write",
                    "finish": "finish",
                }[stage],
                "alone_wall_s": round(alone.get(f"{key}_s", inside["wall_s"]), 3),
                "alone_cpu_s": round(alone.get(f"{key}_cpu_s", inside["thread_cpu_s"]), 3),
                "pipeline_wall_s": round(inside["wall_s"], 3),
                "pipeline_thread_cpu_s": round(inside["thread_cpu_s"], 3),
            }
        )
    records.append(
        {
            "bench": "out_of_core",
            "case": case,
            "impl": "parallel-bound",
            **{k: round(v, 3) if isinstance(v, float) else v for k, v in bound.items()},
            "pipeline_s": round(int_s, 3),
            "pipeline_blocked_on_write_s": round(pipeline["blocked_on_write_s"], 3),
            "throughput_over_bound": round(bound["bound_s"] / int_s, 3),
        }
    )
    return records


def median_stages(runs: list[dict]) -> dict:
    """The median of each stage's times over the streamed runs (`stages.last()` records)."""
    out: dict = {
        k: statistics.median(r[k] for r in runs) for k in ("seconds", "blocked_on_write_s")
    }
    for stage in stages.STAGES:
        out[stage] = {
            k: statistics.median(r[stage][k] for r in runs) for k in ("wall_s", "thread_cpu_s")
        }
    return out


def print_table(records: list[dict], cores: int) -> None:
    """The breakdown as a table on stderr (the JSON lines stay on stdout)."""
    rows = [r for r in records if r["impl"] == "breakdown"]
    print(
        f"\n{'stage':<16} {'alone CPU s':>11} {'alone wall s':>12} {'in pipeline wall s':>19}",
        file=sys.stderr,
    )
    for r in rows:
        print(
            f"{r['stage']:<16} {r['alone_cpu_s']:>11.2f} {r['alone_wall_s']:>12.2f} "
            f"{r['pipeline_wall_s']:>19.2f}",
            file=sys.stderr,
        )
    b = next(r for r in records if r["impl"] == "parallel-bound")
    print(
        f"parallel bound {b['bound_s']:.2f} s ({b['limit']}; serial {b['serial_stage']} "
        f"{b['serial_s']:.2f} s, CPU/{cores} cores {b['cpu_over_cores_s']:.2f} s, finish "
        f"{b['finish_s']:.2f} s); pipeline {b['pipeline_s']:.2f} s: throughput / bound "
        f"{b['throughput_over_bound']:.3f}",
        file=sys.stderr,
    )
