"""Where an integration into a file runs: in memory, streamed slab by slab, or on dask.

`plan_run` validates the window and the spec and picks the way: in memory and saved in the
format the output's suffix names when the window's brick and the chronovolume fit the
memory budget; otherwise streamed z-slab by z-slab into a .zarr store
(`chronocl.integration.runs.streaming.integrate_to_store`); on a dask cluster, one task per slab,
when a client, a scheduler address or a number of local workers is given. `Run.execute`
does the work. `check_run_options` checks what needs no data first, so that a caller can
refuse bad options before it opens anything.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

from chronocl import modes
from chronocl.core.budget import DEFAULT_MEMORY, parse_memory
from chronocl.core.errors import InvalidParameterError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.formats.outputs import output_kind, save_chronovolume
from chronocl.data.series import TimeSeries
from chronocl.engine import check_engine
from chronocl.engine.device_formats import check_device_format
from chronocl.integration.inmemory import Job, at_level, integrate, prepare
from chronocl.integration.runs.plan import fits_in_memory
from chronocl.integration.runs.streaming import integrate_to_store
from chronocl.modes.spec import IntegrationSpec

IN_MEMORY, STREAMED, DASK = "in memory", "streamed", "dask"


def check_run_options(
    out_path: str | os.PathLike,
    memory: str | int | None = None,
    engine: str = "opencl",
    scheduler: str | None = None,
    workers: int | None = None,
) -> int:
    """Check the options that need no data (output format, budget, engine, cluster) before
    any work; return the memory budget in bytes."""
    output_kind(out_path)
    budget = parse_memory(memory)
    check_engine(engine)
    if workers is not None and workers < 1:
        raise InvalidParameterError(f"--workers is {workers}; start at least 1 worker")
    if scheduler is not None:
        check_scheduler(scheduler, workers)
    return budget


def check_scheduler(address: str, workers: int | None = None) -> None:
    """A dask scheduler address: [scheme://]host:port, and no local workers besides."""
    if workers is not None:
        raise InvalidParameterError("give either --scheduler ADDRESS or --workers N, not both")
    try:
        parts = urlsplit(address if "://" in address else f"tcp://{address}")
        ok = bool(parts.hostname) and parts.port is not None and parts.port > 0
    except ValueError:  # a port that is not a number or out of range
        ok = False
    if not ok:
        raise InvalidParameterError(
            f"--scheduler {address!r} is not a scheduler address; write it like "
            "tcp://host:8786 (host and port)"
        )


@dataclass(frozen=True)
class Run:
    """An integration of `job` into `out_path`, planned by `plan_run`; `where` is IN_MEMORY,
    STREAMED or DASK."""

    job: Job
    out_path: Path
    where: str
    budget: int
    engine: str = "opencl"
    device: str | None = None
    client: object = None
    scheduler: str | None = None
    workers: int | None = None
    device_format: str = "auto"

    @property
    def streamed(self) -> bool:
        """Whether the run writes the store slab by slab (locally or on dask); such a run
        resumes when it is run again with the same parameters."""
        return self.where != IN_MEMORY

    def execute(
        self,
        *,
        overwrite: bool = False,
        progress: bool = False,
        on_dashboard: Callable[[str], None] | None = None,
    ) -> Chronovolume | None:
        """Integrate and write `out_path`. Returns the chronovolume when it was integrated in
        memory, None when it was streamed into the store. `on_dashboard` receives the dask
        dashboard's address when the cluster serves one."""
        job = self.job
        if self.where == IN_MEMORY:
            cv = integrate(
                job.series,
                job.selection,
                spec=job.spec,
                engine=self.engine,
                device=self.device,
                progress=progress,
                device_format=self.device_format,
            )
            save_chronovolume(cv, self.out_path, overwrite=overwrite)
            return cv
        args = dict(
            spec=job.spec,
            memory=self.budget,
            engine=self.engine,
            device=self.device,
            overwrite=overwrite,
            progress=progress,
            device_format=self.device_format,
        )
        if self.where == STREAMED:
            integrate_to_store(job.series, job.selection, self.out_path, **args)
        elif self.client is not None:
            integrate_to_store(job.series, job.selection, self.out_path, client=self.client, **args)
        else:
            from chronocl.integration.runs.distributed import connect, dashboard_link

            with connect(self.scheduler, self.workers) as client:
                link = dashboard_link(client)
                if link and on_dashboard is not None:
                    on_dashboard(link)
                integrate_to_store(job.series, job.selection, self.out_path, client=client, **args)
        return None


def plan_run(
    series: TimeSeries,
    window: object = None,
    out_path: str | os.PathLike = "chronovolume.zarr",
    *,
    mode: str = modes.DEFAULT,
    spec: IntegrationSpec | None = None,
    memory: str | int | None = None,
    engine: str = "opencl",
    device: str | None = None,
    client: object = None,
    scheduler: str | None = None,
    workers: int | None = None,
    level: int = 0,
    device_format: str = "auto",
    **spec_args: object,
) -> Run:
    """Validate the integration of `window` of `series` into `out_path` and choose where it runs.

    Arguments as `chronocl.integrate` (mode= and the make_spec arguments, or spec=), plus
    `memory`, the budget ('2GB', bytes; default 2GB); `client`, a dask.distributed Client, or
    `scheduler` (an address) or `workers` (a local cluster of that many processes) to run the
    slabs on dask. Nothing is read or written yet. A window that does not fit the budget needs
    a .zarr output (streamed) or a cluster; any other output raises InvalidParameterError.
    `level` integrates a coarse level of the series (docs/levels.md). `device_format` is what
    bricks travel to the device in (`chronocl.engine.device_formats`).
    """
    budget = check_run_options(out_path, memory, engine, scheduler, workers)
    job = at_level(prepare(series, window, mode, spec, spec_args), level)
    distributed = client is not None or bool(scheduler or workers)
    if distributed:
        where = DASK
    elif fits_in_memory(job, budget, engine):
        where = IN_MEMORY
    elif output_kind(out_path) == ".zarr":
        where = STREAMED
    else:
        raise InvalidParameterError(
            f"this window needs more than --memory {memory or DEFAULT_MEMORY} in memory; "
            "write a .zarr OUT (streamed slab by slab) and convert it, or give a larger --memory"
        )
    check_device_format(device_format, engine, *job.format_input())
    return Run(
        job,
        Path(out_path),
        where,
        budget,
        engine,
        device,
        client,
        scheduler,
        workers,
        device_format,
    )
