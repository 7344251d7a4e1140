"""`chronocl bench` as a function: check everything, measure the matrix on one dask cluster,
write the report folder atomically (`chronocl.integration.scaling` measures,
`chronocl.integration.scaling_report` writes).

Nothing is measured before every input is checked: the store (or the synthetic size), the
windows against its steps, the worker counts against its rows, the devices, the mode and the
output folder, which must be new, empty or an earlier report. The report is built in a hidden
sibling of the output, together with the scratch data (synthetic series, weak-scaling crops,
the runs' outputs), which is removed before the folder is renamed into place.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path

from chronocl.core.atomic import atomic_directory, remove_path
from chronocl.core.errors import InvalidParameterError
from chronocl.core.paths import check_apart, check_input, check_writable
from chronocl.core.progress import meter
from chronocl.data.series import TimeSeries, open_series
from chronocl.integration.scaling import (
    check_matrix,
    check_mode,
    cluster,
    crop_rows,
    default_workers,
    machine,
    make_synthetic,
    measure,
    resolve_devices,
    runs_needed,
)
from chronocl.integration.scaling_report import SCHEMA, check_report_target, write_report

STORE_HINT = "create one with 'chronocl ingest' or 'chronocl generate', or use --synthetic SIZE"


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
    windows = tuple(sorted(set(windows)))
    check_mode(mode)
    if (store is None) == (size_xyz is None):
        raise InvalidParameterError("give a STORE or --synthetic SIZE (one of the two)")
    if repeats < 1:
        raise InvalidParameterError(f"--repeats is {repeats}; time each cell at least once")
    if not windows or windows[0] < 1:
        raise InvalidParameterError("--windows must be whole numbers of at least 1, e.g. 8,16")
    if workers is not None:
        workers = tuple(sorted(set(workers)))
        if not workers or workers[0] < 1:
            raise InvalidParameterError("--workers must be at least 1, e.g. --workers 1,2,4")
    series: TimeSeries | None = None
    if store is not None:
        series = open_series(check_input(store, "store", hint=STORE_HINT))
        volume, n_steps = series.volume_shape, series.n_steps
    else:
        nx, ny, nz = size_xyz  # type: ignore[misc]
        volume, n_steps = (nz, ny, nx), windows[-1]
    check_apart(out, [store])
    replace = check_report_target(out)
    check_writable(out)
    infos = None if scheduler else resolve_devices(devices)
    if workers is None and not scheduler:
        workers = default_workers(os.cpu_count() or 1)
    if workers is not None:
        check_matrix(volume, n_steps, windows, workers)

    with atomic_directory(out, overwrite=replace) as tmp:
        tmp.mkdir()
        scratch = tmp / "scratch"
        scratch.mkdir()
        try:
            report = _measure(
                scratch,
                series,
                size_xyz,
                volume,
                n_steps,
                windows,
                workers,
                devices,
                infos,
                scheduler,
                repeats,
                mode,
                progress,
            )
        finally:
            remove_path(scratch)
        report = write_report(tmp, report)
    return report


def _measure(
    scratch: Path,
    series,
    size_xyz,
    volume,
    n_steps,
    windows,
    workers,
    devices,
    infos,
    scheduler,
    repeats,
    mode,
    progress,
) -> dict:
    """Start (or reach) the cluster, prepare the data, measure; the report's dict."""
    most = workers[-1] if workers else 1
    with cluster(scheduler, most) as (client, addresses):
        if workers is None:  # a scheduler's cluster: as many as it has
            workers = default_workers(len(addresses))
            check_matrix(volume, n_steps, windows, workers)
        if infos is None:  # the devices of the workers' machines
            infos = client.submit(
                resolve_devices, devices, workers=[addresses[0]], pure=False
            ).result()
        unit = volume[0] // workers[-1]
        full = series or make_synthetic(scratch, size_xyz, windows[-1])
        weak = {
            n: crop_rows(full, n * unit, windows[-1], scratch / f"weak-{n}.zarr") for n in workers
        }
        indices = [d.index for d in infos]
        total = runs_needed(volume[0], unit, windows, workers, indices, repeats)
        with meter(total, "measuring", progress, unit="runs") as advance:
            cells, roofline = measure(
                client,
                addresses,
                full,
                weak,
                windows,
                workers,
                indices,
                mode=mode,
                repeats=repeats,
                scratch=scratch,
                local=not scheduler,
                advance=advance,
            )
        address = client.scheduler.address if client.scheduler else scheduler
    nz, ny, nx = volume
    return {
        "schema": SCHEMA,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "machine": machine(),
        "cluster": {
            "kind": "scheduler" if scheduler else "local",
            "address": address,
            "workers": len(addresses),
            "threads_per_worker": 1 if not scheduler else None,
        },
        "devices": [asdict(d) for d in infos],
        "parameters": {
            "input": str(series.path) if series is not None else "synthetic vortex",
            "size_xyz": [nx, ny, nz],
            "dtype": str(full.dtype),
            "itemsize": full.dtype.itemsize,
            "n_steps": n_steps,
            "windows": list(windows),
            "workers": list(workers),
            "devices": indices,
            "repeats": repeats,
            "warmup": 1,
            "mode": mode,
            "weak_rows_per_worker": unit,
        },
        "cells": cells,
        "roofline": roofline,
    }
