"""Integration on a dask.distributed cluster: one task per z-slab of the output.

`chronocl.integration.streaming.integrate_to_store(..., client=client)` plans the slabs and
submits one `slab_task` per slab. A task gets only paths, the spec as a dict and its slab bounds;
on its
worker it opens the series (a shared file system or object store), integrates with that
worker's engine (`get_engine` keeps one OpenCL context per worker process), writes its slab of
the output store directly (slabs are whole output chunks, so no two tasks write one chunk),
leaves a completion marker and returns a small dict. The scheduler therefore moves kilobytes
per task, never voxels. A task lost with its worker is re-run elsewhere; rewriting a slab
writes the same bytes.

Workers must be started with the spawn method: PoCL hangs in a forked child once the parent
holds an OpenCL context. `local_cluster` sets dask's
``distributed.worker.multiprocessing-method`` to ``spawn`` (also dask's default) and uses
processes. A worker without a usable OpenCL device fails its tasks with EngineUnavailableError
naming the worker (no silent fallback to the numpy engine, whose results differ in the last
bits); pass engine="numpy" to run the reference everywhere.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import time
import uuid
from collections.abc import Iterator, Sequence
from pathlib import Path

import zarr

from chronocl.core.errors import (
    ChronoclError,
    EngineUnavailableError,
    InvalidParameterError,
    SlabTaskError,
)
from chronocl.core.memory import aligned_empty
from chronocl.core.progress import meter
from chronocl.data.bricks import Slab
from chronocl.data.series import STEPS_PER_READ, TimeSeries, open_series
from chronocl.engine import get_engine
from chronocl.integration.inmemory import Job
from chronocl.integration.streaming import (
    BrickReader,
    Plan,
    job_from_dict,
    job_to_dict,
    mark_done,
    normalize_slab,
    write_slab,
)

CONNECT_TIMEOUT = 5.0  # seconds before an unreachable scheduler is reported


class SchedulerUnreachableError(ChronoclError, ConnectionError):
    """The dask scheduler address cannot be reached (or is not an address)."""


# -- connecting -------------------------------------------------------------------------------
def use_spawn() -> None:
    """Make dask start worker processes with spawn (PoCL hangs in forked children)."""
    import dask

    dask.config.set({"distributed.worker.multiprocessing-method": "spawn"})


def local_cluster(workers: int, memory_limit: str | int | None = "auto", **kwargs: object):
    """A LocalCluster of `workers` spawned processes with one thread each."""
    from distributed import LocalCluster

    if workers < 1:
        raise InvalidParameterError(f"--workers must be at least 1, got {workers}")
    use_spawn()
    # The workers share this machine: give each PoCL its share of the cores, not all of them.
    cores = str(max(1, (os.cpu_count() or 1) // workers))
    options = {
        "env": {"POCL_MAX_PTHREAD_COUNT": cores, "POCL_CPU_MAX_CU_COUNT": cores},
        "n_workers": workers,
        "threads_per_worker": 1,
        "processes": True,
        "memory_limit": memory_limit,
        "dashboard_address": ":0",
        "silence_logs": logging.ERROR,
        **kwargs,
    }
    return LocalCluster(**options)


def connect_scheduler(address: str, timeout: float = CONNECT_TIMEOUT):
    """A Client of the scheduler at `address`, or SchedulerUnreachableError within `timeout` s."""
    from distributed import Client

    try:
        return Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        detail = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SchedulerUnreachableError(
            f"cannot reach the dask scheduler at {address!r} ({detail}); check the address "
            "(e.g. tcp://host:8786) and that 'dask scheduler' runs there, or use --workers N"
        ) from None


@contextlib.contextmanager
def connect(scheduler: str | None = None, workers: int | None = None) -> Iterator[object]:
    """Yield a Client: of the scheduler at `scheduler`, or of a LocalCluster of `workers`."""
    if scheduler and workers:
        raise InvalidParameterError("give either --scheduler ADDRESS or --workers N, not both")
    if scheduler:
        client = connect_scheduler(scheduler)
        try:
            yield client
        finally:
            client.close()
        return
    from distributed import Client

    with local_cluster(workers or 1) as cluster, Client(cluster, set_as_default=False) as client:
        yield client


def dashboard_link(client: object) -> str | None:
    """The dashboard's address when the scheduler serves one (it needs bokeh)."""
    try:
        services = client.scheduler_info().get("services", {})  # type: ignore[attr-defined]
        return client.dashboard_link if "dashboard" in services else None  # type: ignore[attr-defined]
    except Exception:  # the link is a courtesy; never fail a run over it
        return None


# -- on the workers ---------------------------------------------------------------------------
def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except ValueError:  # not inside a worker (called directly)
        return "local"


def _open(store: str, shape: Sequence[int]) -> TimeSeries:
    series = open_series(store)
    if list(series.shape) != list(shape):
        raise InvalidParameterError(
            f"store {store!r} on worker {_worker_name()} has shape {series.shape}, the client "
            f"saw {tuple(shape)}; give every worker the same data (a shared file system)"
        )
    return series


_held = threading.local()  # a worker may run several tasks at once, one per thread


def _reader(job: Job, rows: int, per_call: int) -> BrickReader:
    """A reader whose brick buffer stays with the worker thread from task to task (no fresh
    pages): one buffer per thread, the size of its largest slab."""
    _, ny, nx = job.series.volume_shape
    key = (job.series.dtype.str, job.selection.width, ny, nx)
    brick = getattr(_held, "brick", {})
    held = brick.get(key)
    if held is None or held[0].shape[0] < rows:
        held = [aligned_empty((rows, *key[1:]), job.series.dtype)]
        _held.brick = {key: held}
    return BrickReader(job.series, rows, job.selection.width, held, per_call)


def slab_task(
    job: dict, bounds: tuple[int, int, int, int], out: str, digest: str, engine: str, device
) -> dict:
    """Integrate and write one slab; returns {"slab", "max", "seconds", "bytes", "worker"}."""
    t0 = time.perf_counter()
    series = _open(job["store"], job["shape"])
    j = job_from_dict(job, series)
    try:
        eng = get_engine(engine, device)
    except EngineUnavailableError as exc:
        raise EngineUnavailableError(f"worker {_worker_name()}: {exc}") from None
    s = Slab(*bounds)
    per_call = int(job.get("steps_per_read", STEPS_PER_READ))
    brick = _reader(j, s.r1 - s.r0, per_call).read(j.selection.steps, s.r0, s.r1)
    partial, final = eng.accumulate(
        brick, s.crop, j.selection.steps, j.positions, j.order, j.spec, j.value_range
    )
    del brick
    peak = write_slab(zarr.open_group(store=out, mode="r+"), j, s, partial, final)
    seconds = time.perf_counter() - t0
    mark_done(Path(out), "slab", s, digest, max=peak, seconds=seconds)
    return {
        "slab": s.z0,
        "max": peak,
        "seconds": seconds,
        "bytes": (s.r1 - s.r0) * j.row_bytes,
        "worker": _worker_name(),
    }


def normalize_task(
    bounds: tuple[int, int, int, int], out: str, digest: str, chunk_rows: int, peak: float
) -> dict:
    """The second pass of additive/max for one slab."""
    t0 = time.perf_counter()
    s = Slab(*bounds)
    normalize_slab(zarr.open_group(store=out, mode="r+"), s, chunk_rows, peak)
    mark_done(Path(out), "norm", s, digest)
    return {"slab": s.z0, "seconds": time.perf_counter() - t0}


# -- on the client ----------------------------------------------------------------------------
TASKS_PER_THREAD = 4  # enough slabs for every worker thread to take several (load balance)


def slab_rows_for(client, nz: int) -> int:
    """At most this many rows per slab, so the cluster's threads all get work."""
    try:
        threads = max(1, sum(client.nthreads().values()))
    except Exception:  # an unusual client; slabs then follow the memory budget alone
        return nz
    return max(1, -(-nz // (threads * TASKS_PER_THREAD)))


def task_args(job: Job) -> dict:
    """What every slab task gets besides its bounds: paths and the spec, a few kilobytes."""
    return {**job_to_dict(job), "shape": list(job.series.shape)}


def _gather(client, futures: list, total: int, done: int, label: str, progress: bool) -> list:
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    results = []
    try:
        with meter(total, label, progress, done) as advance:
            for future in as_completed(futures, loop=client.loop):
                info = future.result()
                results.append(info)
                advance(int(info.get("bytes", 0)))
    except KilledWorker as exc:
        client.cancel(futures)
        raise SlabTaskError(
            f"a slab task killed its workers repeatedly ({exc}); check the workers' memory "
            "(lower --memory) and run the same command again to resume"
        ) from None
    except BaseException:
        client.cancel(futures)
        raise
    return results


def run_slab_tasks(
    client,
    job: Job,
    plan: Plan,
    tmp: Path,
    digest: str,
    todo: Sequence[Slab],
    engine: str,
    device: str | None,
    progress: bool,
) -> list[dict]:
    """Submit one task per slab still to do and wait for all; returns their small results."""
    args = {**task_args(job), "steps_per_read": plan.steps_per_read}
    return _per_slab(
        client,
        "slab",
        slab_task,
        todo,
        lambda b: (args, b, str(tmp), digest, engine, device),
        len(plan.slabs),
        "integrating slabs",
        progress,
    )


def _per_slab(client, kind: str, task, todo, args_of, total: int, label: str, progress) -> list:
    """Run task(*args_of(bounds)) for every slab in `todo`, under keys of this run; wait."""
    run = uuid.uuid4().hex[:8]
    futures = [
        client.submit(
            task,
            *args_of((s.z0, s.z1, s.r0, s.r1)),
            key=f"chronocl-{kind}-{s.z0}-{run}",
            pure=False,
        )
        for s in todo
    ]
    return _gather(client, futures, total, total - len(todo), label, progress)


def run_normalize_tasks(
    client,
    plan: Plan,
    tmp: Path,
    digest: str,
    todo: Sequence[Slab],
    peak: float,
    progress: bool,
) -> list[dict]:
    return _per_slab(
        client,
        "norm",
        normalize_task,
        todo,
        lambda b: (b, str(tmp), digest, plan.chunk_rows, peak),
        len(plan.slabs),
        "normalising",
        progress,
    )
