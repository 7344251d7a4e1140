"""`chronocl bench` as a function: check everything, measure the matrix on one dask cluster,
write the report folder atomically (`chronocl.report.scaling` measures,
`chronocl.report.scaling_report` writes).

Nothing is measured before every input is checked: the store (or the synthetic size), the
windows against its steps, the worker counts against its rows, the devices, the mode and the
output folder, which must be new, empty or an earlier report. The report is built in a hidden
sibling of the output, together with the scratch data (synthetic series, weak-scaling crops,
the runs' outputs), which is removed before the folder is renamed into place.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

from chronocl import modes
from chronocl.core.atomic import atomic_directory, remove_path
from chronocl.core.errors import InvalidParameterError
from chronocl.core.paths import check_apart, check_input, check_writable
from chronocl.core.progress import meter
from chronocl.data.series import TimeSeries, open_series
from chronocl.report.scaling import (
    check_matrix,
    cluster,
    crop_rows,
    default_workers,
    machine,
    make_synthetic,
    measure,
    resolve_devices,
    runs_needed,
)
from chronocl.report.scaling_report import SCHEMA, check_report_target, write_report

STORE_HINT = "create one with 'chronocl ingest' or 'chronocl generate', or use --synthetic SIZE"
MAX_SYNTHETIC_VOXELS = 2**30  # a step is computed in memory (as 'chronocl generate')


@dataclass(frozen=True)
class Request:
    """A checked report request: the data, the matrix and how to run it."""

    series: TimeSeries | None  # the user's store, or None: synthetic at size_xyz
    size_xyz: tuple[int, int, int]
    n_steps: int
    windows: tuple[int, ...]
    workers: tuple[int, ...] | None  # None: as many as the scheduler's cluster has
    devices: str | None
    infos: tuple | None  # the devices resolved here (a local cluster), else on a worker
    scheduler: str | None
    repeats: int
    mode: str
    progress: bool

    @property
    def volume_zyx(self) -> tuple[int, int, int]:
        nx, ny, nz = self.size_xyz
        return nz, ny, nx


def run_report(
    out: str | os.PathLike,
    *,
    store: str | os.PathLike | None = None,
    size_xyz: Sequence[int] | None = None,
    windows: Sequence[int] = (8, 16, 32, 64),
    workers: Sequence[int] | None = None,
    devices: str | None = None,
    scheduler: str | None = None,
    repeats: int = 3,
    mode: str = "alpha",
    progress: bool = False,
) -> dict:
    """Measure and write the scalability report to the folder `out`; returns report.json's dict.

    Either `store` (a series store) or `size_xyz` (the synthetic vortex at that size, as
    many steps as the largest window). `workers` defaults to 1, 2, 4, ... up to this machine's
    cores (or the scheduler's workers); `devices` is None (the chosen device), 'all' or a
    comma list of indices or name parts.
    """
    modes.get(mode)  # an unknown mode: one line, before any work
    if (store is None) == (size_xyz is None):
        raise InvalidParameterError("give a STORE or --synthetic SIZE (one of the two)")
    if repeats < 1:
        raise InvalidParameterError(f"--repeats is {repeats}; time each cell at least once")
    windows = tuple(sorted(set(windows)))
    if not windows or windows[0] < 1:
        raise InvalidParameterError("--windows must be whole numbers of at least 1, e.g. 8,16")
    if workers is not None:
        workers = tuple(sorted(set(workers)))
        if not workers or workers[0] < 1:
            raise InvalidParameterError("--workers must be at least 1, e.g. --workers 1,2,4")
    series: TimeSeries | None = None
    if store is not None:
        # absolute: a remote cluster's workers open it from their own working folders
        series = open_series(check_input(store, "store", hint=STORE_HINT).absolute())
        nz, ny, nx = series.volume_shape
        size, n_steps = (nx, ny, nz), series.n_steps
    else:
        size, n_steps = _check_size(size_xyz), windows[-1]
    check_apart(out, [store])
    replace_earlier = check_report_target(out)
    check_writable(out)
    if workers is None and not scheduler:
        workers = default_workers(os.cpu_count() or 1)
    request = Request(
        series=series,
        size_xyz=size,
        n_steps=n_steps,
        windows=windows,
        workers=workers,
        devices=devices,
        infos=None if scheduler else tuple(resolve_devices(devices)),
        scheduler=scheduler,
        repeats=repeats,
        mode=mode,
        progress=progress,
    )
    if workers is not None:
        check_matrix(request.volume_zyx, n_steps, windows, workers)

    with atomic_directory(out, overwrite=replace_earlier) as tmp:
        tmp.mkdir()
        scratch = (tmp / "scratch").absolute()
        scratch.mkdir()
        try:
            report = _measure(request, scratch)
        finally:
            remove_path(scratch)
        report = write_report(tmp, report)
    return report


def _check_size(size_xyz: Sequence[int]) -> tuple[int, int, int]:
    size = tuple(int(n) for n in size_xyz)
    if len(size) != 3 or min(size) < 1 or size[0] * size[1] * size[2] > MAX_SYNTHETIC_VOXELS:
        raise InvalidParameterError(
            f"synthetic size {size_xyz} must be three sides of at least 1 and at most "
            f"{MAX_SYNTHETIC_VOXELS // 2**20} Mi voxels, e.g. --synthetic 256"
        )
    return size  # type: ignore[return-value]


def _measure(req: Request, scratch: Path) -> dict:
    """Start (or reach) the cluster, prepare the data, measure; the report's dict."""
    most = req.workers[-1] if req.workers else 1
    windows, volume = req.windows, req.volume_zyx
    with cluster(req.scheduler, most) as (client, addresses):
        if req.workers is None:  # a scheduler's cluster: as many workers as it has
            req = replace(req, workers=default_workers(len(addresses)))
            check_matrix(volume, req.n_steps, windows, req.workers)
        if req.infos is None:  # the devices of the workers' machines
            found = client.submit(resolve_devices, req.devices, workers=[addresses[0]], pure=False)
            req = replace(req, infos=tuple(found.result()))
        workers, infos = req.workers, req.infos
        unit = volume[0] // workers[-1]
        full = req.series or make_synthetic(scratch, req.size_xyz, windows[-1], req.progress)
        weak = {
            n: crop_rows(full, n * unit, windows[-1], scratch / f"weak-{n}.zarr") for n in workers
        }
        indices = [d.index for d in infos]
        total = runs_needed(volume[0], unit, windows, workers, indices, req.repeats)
        with meter(total, "measuring", req.progress, unit="runs") as advance:
            cells, roofline = measure(
                client,
                addresses,
                full,
                weak,
                windows,
                workers,
                indices,
                mode=req.mode,
                repeats=req.repeats,
                scratch=scratch,
                local=not req.scheduler,
                advance=advance,
            )
        address = client.scheduler.address if client.scheduler else req.scheduler
    return {
        "schema": SCHEMA,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": machine(),
        "cluster": {
            "kind": "scheduler" if req.scheduler else "local",
            "address": address,
            "workers": len(addresses),
            "threads_per_worker": None if req.scheduler else 1,
        },
        "devices": [asdict(d) for d in infos],
        "parameters": {
            "input": str(req.series.path) if req.series is not None else "synthetic vortex",
            "size_xyz": list(req.size_xyz),
            "dtype": str(full.dtype),
            "itemsize": full.dtype.itemsize,
            "n_steps": req.n_steps,
            "windows": list(windows),
            "workers": list(workers),
            "devices": indices,
            "repeats": req.repeats,
            "warmup": 1,
            "mode": req.mode,
            "weak_rows_per_worker": unit,
        },
        "cells": cells,
        "roofline": roofline,
    }
