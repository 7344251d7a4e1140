"""The dask executor: an out-of-core run's slab tasks on a dask.distributed cluster.

`chronocl.integration.runs.streaming.integrate_to_store(..., client=client)` plans the slabs and
`DaskExecutor` submits one task per slab: the same slab task the local executor runs
(`streaming.SlabTask`), in the small form it travels in (`SlabTask.remote`): paths, the spec
as a dict and the slab's bounds. On its worker it opens the series (a shared file system or
object store), integrates with that worker's engine (`get_engine` keeps one OpenCL context
per worker process), writes its slab of the output store directly (slabs are whole output
chunks, so no two tasks write one chunk), leaves a completion marker and returns a small
dict. The scheduler therefore moves kilobytes per task, never voxels. A task lost with its
worker is re-run elsewhere; rewriting a slab writes the same bytes.

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
import uuid
from collections.abc import Callable, Iterator, Sequence

from chronocl.core.errors import (
    ChronoclError,
    EngineUnavailableError,
    InvalidParameterError,
    SlabTaskError,
)
from chronocl.core.progress import meter
from chronocl.core.tuning import TUNING
from chronocl.data.bricks import Slab
from chronocl.data.series import TimeSeries, open_series
from chronocl.engine import get_engine
from chronocl.engine.base import Engine
from chronocl.integration.inmemory import Job
from chronocl.integration.runs.local import Bounds, SlabWork
from chronocl.integration.runs.plan import Plan


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


def connect_scheduler(address: str, timeout: float | None = None):
    """A Client of the scheduler at `address`, or SchedulerUnreachableError within `timeout` s
    (None: `TUNING.connect_timeout_s`)."""
    timeout = TUNING.connect_timeout_s if timeout is None else timeout
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


def dashboard_link(client) -> str | None:
    """The dashboard's address when the scheduler serves one (it needs bokeh)."""
    try:
        services = client.scheduler_info().get("services", {})
        return client.dashboard_link if "dashboard" in services else None
    except Exception:  # the link is a courtesy; never fail a run over it
        return None


# -- on the workers ---------------------------------------------------------------------------
def worker_name() -> str:
    """The address of the dask worker running this code ("local" outside any)."""
    try:
        from distributed import get_worker

        return get_worker().address
    except ValueError:  # not inside a worker (called directly)
        return "local"


def open_on_worker(store: str, shape: Sequence[int]) -> TimeSeries:
    """The series at `store` as this worker sees it, checked to have the client's `shape`."""
    series = open_series(store)
    if list(series.shape) != list(shape):
        raise InvalidParameterError(
            f"store {store!r} on worker {worker_name()} has shape {series.shape}, the client "
            f"saw {tuple(shape)}; give every worker the same data (a shared file system)"
        )
    return series


def engine_on_worker(name: str, device: str | None) -> Engine:
    """This worker's engine; EngineUnavailableError naming the worker when it has none."""
    try:
        return get_engine(name, device)
    except EngineUnavailableError as exc:
        raise EngineUnavailableError(f"worker {worker_name()}: {exc}") from None


# -- on the client ----------------------------------------------------------------------------


def slab_rows_for(client, nz: int) -> int:
    """At most this many rows per slab, so the cluster's threads all get work."""
    try:
        threads = max(1, sum(client.nthreads().values()))
    except Exception:  # an unusual client; slabs then follow the memory budget alone
        return nz
    return max(1, -(-nz // (threads * TUNING.tasks_per_thread)))


class DaskExecutor:
    """Runs slab tasks on the workers of `client`: one submitted task per slab."""

    read_ahead = False  # a task reads its one brick and writes it: nothing to overlap

    def __init__(self, client, progress: bool = False) -> None:
        self.client = client
        self.progress = progress

    def max_rows(self, job: Job) -> int:
        """At most this many rows per slab, so that every worker thread gets several."""
        return slab_rows_for(self.client, job.series.volume_shape[0])

    def run_slabs(self, task: SlabWork, plan: Plan, todo: Sequence[Slab], total: int) -> list:
        """Submit the slab task for each slab of `todo` (of `total`); their small results."""
        return self.run(task.remote(), todo, total, "integrating slabs")

    def run(
        self, task: Callable[[Bounds], dict], todo: Sequence[Slab], total: int, label: str
    ) -> list[dict]:
        """Submit task(bounds) for every slab in `todo`, under keys of this run, and wait."""
        run, name = uuid.uuid4().hex[:8], type(task).__name__.lower()
        futures = [
            self.client.submit(task, s.bounds, key=f"chronocl-{name}-{s.z0}-{run}", pure=False)
            for s in todo
        ]
        return gather(self.client, futures, total, total - len(todo), label, self.progress)


def gather(client, futures: list, total: int, done: int, label: str, progress: bool) -> list:
    """The results of `futures` as they finish (a progress bar); cancels the rest on failure."""
    from distributed import KilledWorker, as_completed

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
