"""Integration larger than memory: z-slabs streamed from the series into a chronovolume store.

`integrate_to_store` plans slabs that fit the memory budget (`chronocl.integration.runs.plan`),
opens or resumes the run's store (`chronocl.integration.runs.runstore`) and has an executor run
one `SlabTask` per slab not yet done: read the slab's brick (rows plus gradient halo, all W
steps), integrate it, write it into the store and leave its marker. The local executor
(`chronocl.integration.runs.local`) runs the task in this process, reading ahead and writing
behind; the dask executor (`chronocl.integration.runs.distributed`) submits it to a cluster, in
the small form that travels (`SlabTask.remote`). Both write the same bytes and the same
markers, so a run cut short on one resumes on the other.

A mode whose finalisation is global (`IntegrationSpec.finalize_is_global`) writes raw
partials and is finished by a second pass over the output chunks (`runstore.FinishTask`).
A run that fails before any slab is finished, or on bad input (a ChronoclError), removes
its partial; otherwise running it again with the same parameters resumes.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import zarr

from chronocl import modes, reference
from chronocl.core.atomic import RUN_DIR
from chronocl.core.budget import bound_allocator, parse_memory
from chronocl.core.errors import InvalidParameterError
from chronocl.core.paths import check_apart, check_output
from chronocl.core.selection import Selection
from chronocl.core.tuning import TUNING
from chronocl.data.bricks import BrickSource, SeriesBricks, Slab
from chronocl.data.series import TimeSeries
from chronocl.data.writer import compressors
from chronocl.engine import check_engine, get_engine
from chronocl.engine.device_formats import check_device_format, with_device_format
from chronocl.integration.inmemory import Job, Out, integrate_brick, prepare
from chronocl.integration.runs import distributed, stages
from chronocl.integration.runs.distributed import DaskExecutor
from chronocl.integration.runs.local import Bounds, LocalExecutor
from chronocl.integration.runs.plan import (
    READ_OPTIONS,
    Plan,
    fits_in_memory,
    plan_slabs,
    slab_bytes,
)
from chronocl.integration.runs.runstore import (
    FinishTask,
    commit,
    done_slabs,
    drop_unless_resumable,
    mark_done,
    open_run,
    output_array,
    partial_path,
    run_hash,
    target_of,
    volume_maxima,
)
from chronocl.integration.visibility import warn_invisible
from chronocl.modes.base import Partial
from chronocl.modes.spec import IntegrationSpec

__all__ = [
    "READ_OPTIONS",
    "RUN_DIR",
    "SlabTask",
    "fits_in_memory",
    "integrate_to_store",
    "partial_path",
    "plan_slabs",
    "slab_bytes",
    "write_slab",
]

log = logging.getLogger("chronocl")


# -- the slab task ----------------------------------------------------------------------------
def write_slab(
    group: zarr.Group, job: Job, slab: Slab, partial: Partial, final: bool
) -> list[float] | None:
    """Write one integrated slab; returns the per-channel maxima of a raw partial that a
    global finalisation needs (`IntegrationSpec.finalize_is_global`), else None."""
    raw = job.spec.finalize_is_global
    rgba = partial.rgba
    if not final and not raw:  # per-voxel finalisation (the numpy engine leaves it to us)
        rgba = reference.finalize(partial, job.positions, job.spec)
    output_array(group, "rgba_raw" if raw else "rgba")[slab.z0 : slab.z1] = rgba
    if partial.t_index is not None:
        output_array(group, "t_index")[slab.z0 : slab.z1] = partial.t_index
    return rgba.reshape(-1, 4).max(axis=0).tolist() if raw else None


@dataclass(frozen=True)
class SlabTask:
    """One slab of a run: integrate its brick, write it into the run's store at `store`,
    then leave its marker under the run's hash `digest`.

    The one task of both executors: the local one calls `integrate` and `write` in turn
    (overlapping slabs), the dask one submits `remote()`, which calls the task on a worker.
    """

    job: Job
    store: Path
    digest: str
    engine: str = "opencl"
    device: str | None = None
    steps_per_read: int = field(default_factory=lambda: TUNING.steps_per_read)
    device_format: str = "auto"  # what bricks travel to the device in (engine.device_formats)

    @cached_property
    def group(self) -> zarr.Group:
        return zarr.open_group(store=str(self.store), mode="r+")

    def integrate(self, slab: Slab, brick: np.ndarray, out: Out | None = None):
        """The slab's partial and whether it is final (into `out` if given)."""
        eng = get_engine(self.engine, self.device)
        eng = with_device_format(eng, self.device_format, *self.job.format_input())
        return integrate_brick(self.job, eng, slab, brick, out)

    def write(self, slab: Slab, partial: Partial, final: bool, started: float) -> dict:
        """Write the slab and its marker; {"slab", "seconds", "bytes" read[, "maxima"]}."""
        maxima = write_slab(self.group, self.job, slab, partial, final)
        seconds = time.perf_counter() - started
        info = {} if maxima is None else {"maxima": maxima}
        mark_done(self.store, "slab", slab, self.digest, seconds=seconds, **info)
        read = (slab.r1 - slab.r0) * self.job.row_bytes
        return {"slab": slab.z0, "seconds": seconds, "bytes": read, **info}

    def __call__(self, slab: Slab, bricks: BrickSource) -> dict:
        """Read, integrate and write one slab."""
        started = time.perf_counter()
        brick = bricks.read(self.job.selection.steps, slab.r0, slab.r1)
        partial, final = self.integrate(slab, brick)
        del brick
        return self.write(slab, partial, final, started)

    def remote(self) -> RemoteSlabTask:
        """This task as it travels to a dask worker: paths, the spec and numbers."""
        return RemoteSlabTask(
            job_to_dict(self.job),
            str(self.store),
            self.digest,
            self.engine,
            self.device,
            self.steps_per_read,
            self.device_format,
        )


@dataclass(frozen=True)
class RemoteSlabTask:
    """A `SlabTask` in transit, a few kilobytes; called with a slab's bounds on a worker, it
    opens the series and the worker's engine and runs the task."""

    job: dict
    store: str
    digest: str
    engine: str
    device: str | None
    steps_per_read: int
    device_format: str = "auto"

    def __call__(self, bounds: Bounds) -> dict:
        bound_allocator()  # as the local executor: a worker's threads hand freed blocks back
        series = distributed.open_on_worker(self.job["store"], self.job["shape"])
        job = job_from_dict(self.job, series)
        distributed.engine_on_worker(self.engine, self.device)
        task = SlabTask(
            job,
            Path(self.store),
            self.digest,
            self.engine,
            self.device,
            device_format=self.device_format,
        )
        slab = Slab(*bounds)
        width = job.selection.width
        # The brick buffer stays with the worker's thread from task to task (no fresh pages).
        bricks = SeriesBricks.per_thread(series, slab.r1 - slab.r0, width, self.steps_per_read)
        return {**task(slab, bricks), "worker": distributed.worker_name()}


def job_to_dict(job: Job) -> dict:
    """The small, picklable description of a job a worker rebuilds with `job_from_dict`."""
    if job.series.path is None:
        raise InvalidParameterError(
            "distributed integration reads the series from its store on every worker; "
            "save it first (series.save('data.zarr')) and open it with chronocl.open"
        )
    return {
        "store": str(job.series.path),
        "shape": list(job.series.shape),
        "steps": list(job.selection.steps),
        "n_steps": job.selection.n_steps,
        "spec": job.spec.to_dict(),
        "value_range": [float(v) for v in job.value_range],
    }


def job_from_dict(d: dict, series: TimeSeries) -> Job:
    selection = Selection(tuple(d["steps"]), int(d["n_steps"]))
    value_range = (float(d["value_range"][0]), float(d["value_range"][1]))
    return Job.of(series, selection, IntegrationSpec.from_dict(d["spec"]), value_range)


# -- the run ----------------------------------------------------------------------------------
def integrate_to_store(
    series: TimeSeries,
    window: object = None,
    out_path: str | os.PathLike = "chronovolume.zarr",
    *,
    spec: IntegrationSpec | None = None,
    memory: str | int | None = None,
    engine: str = "opencl",
    device: str | None = None,
    slab: int | None = None,
    overwrite: bool = False,
    progress: bool = False,
    client: object = None,
    compressor: str = "blosc-lz4",
    device_format: str = "auto",
    **spec_args: object,
) -> Path:
    """Integrate the window of `series` slab by slab into the chronovolume store `out_path`.

    Arguments as `chronocl.integrate` (mode= and the make_spec arguments, or spec=), plus
    `memory`, the budget ('2GB', '512MiB', bytes; default 2GB) that sets the slab size
    (per worker with a client), `slab`, at most this many rows per slab, and `client`, a
    dask.distributed Client that runs one task per slab on its workers (see
    `chronocl.integration.runs.distributed`). `compressor` compresses the output chunks:
    blosc-lz4 (default; as small as zstd here and about twice as fast to write), zstd (as
    `Chronovolume.save`)
    or none. `device_format` is what bricks travel to the device in (`chronocl.integrate`).
    A run interrupted or failed (other than on bad input) leaves its finished slabs
    behind; running it again with the same parameters resumes. Returns the path written;
    `Chronovolume.load` reads it.
    """
    check_apart(out_path, [series.path])  # never onto, into or around the input
    target = check_output(out_path, overwrite)
    name = str(target).lower().rstrip("/")
    if not name.endswith(".zarr") or name.endswith(".ome.zarr"):
        raise InvalidParameterError(
            f"streamed output {str(target)!r} must be a chronocl .zarr store; "
            "convert it afterwards, or give a larger --memory to write .vti / .ome.zarr"
        )
    check_engine(engine)
    mode = str(spec_args.pop("mode", modes.DEFAULT))
    job = prepare(series, window, mode, spec, spec_args)
    check_device_format(device_format, engine, *job.format_input())
    warn_invisible(job)  # steps the transfer functions hide: said before hours of streaming
    budget = parse_memory(memory)
    if client is None:
        executor: LocalExecutor | DaskExecutor = LocalExecutor(get_engine(engine, device), progress)
    else:
        executor = DaskExecutor(client, progress)
    rows = executor.max_rows(job)
    plan = plan_slabs(job, budget, engine, rows, slab, read_ahead=executor.read_ahead)
    compressors(compressor)  # an unknown name fails before any work
    # A device format other than auto changes the bytes, so it is part of the run's identity.
    label = engine if device_format == "auto" else f"{engine}:{device_format}"
    digest = run_hash(job, label, plan.chunk_rows, compressor)
    tmp = partial_path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    lock = open_run(tmp, job, plan, digest, compressor)
    times = stages.begin()
    try:
        task = SlabTask(job, tmp, digest, engine, device, plan.steps_per_read, device_format)
        run(task, plan, executor)
        with times.stage("finish"):
            commit(tmp, target, job, engine, overwrite)
        times.end()
    except BaseException as exc:
        drop_unless_resumable(tmp, digest, exc)
        raise
    finally:
        os.close(lock)
    return target


def run(task: SlabTask, plan: Plan, executor: LocalExecutor | DaskExecutor) -> None:
    """Run the slabs of `plan` that the run at `task.store` has not finished (and the
    second pass of a global finalisation) on `executor`."""
    tmp, digest, job = task.store, task.digest, task.job
    done = done_slabs(tmp, "slab", digest)
    todo = [s for s in plan.slabs if (s.z0, s.z1) not in done]
    if done:
        n = len(plan.slabs)
        log.info("resuming %s: %d of %d slabs already written", target_of(tmp), len(done), n)
    executor.run_slabs(task, plan, todo, len(plan.slabs))

    if job.spec.finalize_is_global:
        maxima = tuple(volume_maxima(tmp, plan, digest))
        positions = tuple(float(p) for p in job.positions)
        spec = job.spec.to_dict()
        finish = FinishTask(str(tmp), digest, plan.chunk_rows, maxima, positions, spec)
        finished = done_slabs(tmp, "norm", digest)
        rest = [s for s in plan.slabs if (s.z0, s.z1) not in finished]
        executor.run(finish, rest, len(plan.slabs), "normalising")
