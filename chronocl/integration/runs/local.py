"""The local executor: an out-of-core run's slab tasks in this process.

It runs the same slab task a dask worker runs (`chronocl.integration.runs.streaming.SlabTask`:
integrate one slab, write it, leave its marker), overlapping its steps: the next brick is
read on one thread while this one is integrated, and the slab before is written on another,
into two output buffers used in turn. Memory stays what the plan counted
(`chronocl.integration.runs.plan.slab_bytes`); a `GrowthGuard` hands freed pages back when the
process grows past it. Each stage's calls are timed (`chronocl.integration.runs.stages`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Protocol

import numpy as np

from chronocl.core.budget import GrowthGuard, bound_allocator
from chronocl.core.memory import aligned_empty
from chronocl.core.progress import meter
from chronocl.data.bricks import BrickSource, SeriesBricks, Slab
from chronocl.engine.base import Engine
from chronocl.integration.inmemory import Job, Out, engine_rows, integrate_slabs
from chronocl.integration.runs import stages
from chronocl.integration.runs.plan import Plan
from chronocl.modes.base import Partial

Bounds = tuple[int, int, int, int]  # Slab.bounds


class SlabWork(Protocol):
    """What an executor runs per slab: `chronocl.integration.runs.streaming.SlabTask`."""

    job: Job

    def integrate(
        self, slab: Slab, brick: np.ndarray, out: Out | None = None
    ) -> tuple[Partial, bool]:
        """Integrate the slab's brick (into `out` if given)."""
        ...

    def write(self, slab: Slab, partial: Partial, final: bool, started: float) -> dict:
        """Write the slab into the run's store and leave its marker; a small result."""
        ...

    def remote(self) -> Callable[[Bounds], dict]:
        """The task as it travels to a worker: a small picklable callable of a slab's bounds."""
        ...


class LocalExecutor:
    """Runs slab tasks here with `engine`, reading ahead and writing behind."""

    read_ahead = True  # plan for the next brick read while one is integrated

    def __init__(self, engine: Engine, progress: bool = False) -> None:
        self.engine = engine
        self.progress = progress

    def max_rows(self, job: Job) -> int:
        """At most this many rows per slab: what fits the engine's brick."""
        return engine_rows(self.engine, job)

    def run_slabs(self, task: SlabWork, plan: Plan, todo: Sequence[Slab], total: int) -> None:
        """Integrate and write the slabs `todo` (of `total`)."""
        job = task.job
        _, ny, nx = job.series.volume_shape
        rows = plan.slab_rows
        bound_allocator()  # freed blocks go back to the system, however many threads free them
        guard = GrowthGuard(plan.peak_bytes)  # before the buffers, which the plan counts
        times = stages.current()
        buffers = [
            (
                aligned_empty((rows, ny, nx, 4), np.float32),
                aligned_empty((rows, ny, nx), np.int32) if job.spec.has_t_index else None,
            )
            for _ in range(2)
        ]
        writes: list[Future | None] = [None, None]
        count = 0

        def out(s: Slab) -> Out:
            nonlocal count
            k, count = count % 2, count + 1
            if writes[k] is not None:
                w0 = time.perf_counter()
                writes[k].result()  # the slab before last has left this buffer
                times.blocked += time.perf_counter() - w0
            rgba, t_index = buffers[k]
            n = s.z1 - s.z0  # a leading-axis prefix of a C-contiguous buffer is contiguous
            return rgba[:n], None if t_index is None else t_index[:n]

        with (
            meter(total, "integrating slabs", self.progress, total - len(todo)) as advance,
            ThreadPoolExecutor(max_workers=1, thread_name_prefix="chronocl-write") as writer,
        ):

            def finish(s: Slab, partial: Partial, final: bool, t0: float) -> None:
                with times.stage("write"):
                    info = task.write(s, partial, final, t0)
                guard.check()
                advance(info["bytes"])

            t0 = time.perf_counter()
            bricks = _Timed(
                SeriesBricks.buffered(
                    job.series,
                    rows + 2 * job.halo,
                    job.selection.width,
                    2 if plan.read_ahead else 1,
                    plan.steps_per_read,
                ),
                times,
            )

            def integrate(s: Slab, brick: np.ndarray, o: Out | None) -> tuple[Partial, bool]:
                with times.stage("integrate"):
                    return task.integrate(s, brick, o)

            steps = job.selection.steps
            results = integrate_slabs(todo, steps, bricks, integrate, out, plan.read_ahead)
            for i, (s, partial, final) in enumerate(results):
                writes[i % 2] = writer.submit(finish, s, partial, final, t0)
                t0 = time.perf_counter()
            for w in writes:
                if w is not None:
                    w.result()

    def run(
        self, task: Callable[[Bounds], dict], todo: Sequence[Slab], total: int, label: str
    ) -> None:
        """Run a per-slab task (e.g. a `runstore.FinishTask`) on the slabs `todo`, in turn."""
        times = stages.current()
        with meter(total, label, self.progress, total - len(todo)) as advance:
            for s in todo:
                with times.stage("finish"):
                    info = task(s.bounds)
                advance(int(info.get("bytes", 0)))


class _Timed:
    """A brick source whose reads count as the run's read stage."""

    def __init__(self, bricks: BrickSource, times: stages.StageTimes) -> None:
        self.bricks, self.times = bricks, times

    def read(self, steps: Sequence[int], z0: int, z1: int):
        with self.times.stage("read"):
            return self.bricks.read(steps, z0, z1)
