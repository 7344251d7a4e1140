"""The scalability report's measurements (`chronocl bench`): integration throughput against
window length, volume size, worker count and device, beside the read roofline.

One dask cluster serves the whole matrix: a LocalCluster of the largest worker count (spawned
processes, one thread each, each with its share of the cores) or the cluster at a scheduler
address. A cell of n workers restricts its tasks to the first n of them (`dask.annotate`),
so a worker is the same unit of resources in every cell. A cell is one `integrate_to_store`
of the window 0:W, store to store as a real run (read, integrate, write; one task per
z-slab), timed as the median of `repeats` runs after one warm-up (and, before the first
cell, one untimed run per device on the workers of the largest count, which build their
kernels at once).

Strong scaling: the whole volume, every window, every worker count. Weak scaling: the
largest window over the first n·u z-rows with n workers (u = Z // the largest worker
count), so every worker has u rows. Synthetic data and the weak-scaling crops are written to
a scratch folder the caller gives (on a file system the workers share). The read roofline
(`chronocl.engine.roofline`, plus reading the window from the store) is measured where the
work runs: in this process beside a local cluster, on a worker of a remote one.
"""

from __future__ import annotations

import contextlib
import os
import platform
import statistics
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from chronocl.core.atomic import remove_path
from chronocl.core.errors import EngineUnavailableError, InvalidParameterError
from chronocl.core.timing import race_times
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries, open_series, write_series
from chronocl.engine.device import (
    NO_PLATFORM,
    DeviceInfo,
    list_devices,
    no_build_error,
    pick_device,
    usable_devices,
)
from chronocl.engine.roofline import read_roofline
from chronocl.integration.runs import distributed
from chronocl.integration.runs.streaming import integrate_to_store

MAX_SIDE = 4096
ROOFLINE_BYTES = 512 * 2**20  # the roofline reads at most this much of the window


# -- parsing and checking (before any work) ---------------------------------------------------
def parse_counts(text: str, option: str, example: str) -> tuple[int, ...]:
    """'8,16,32' as sorted distinct positive integers; one line naming the fix otherwise."""
    try:
        values = sorted({int(v) for v in text.split(",")})
    except ValueError:
        values = []
    if not values or values[0] < 1:
        raise InvalidParameterError(
            f"{option} {text!r} must be whole numbers of at least 1 separated by commas, "
            f"e.g. {option} {example}"
        )
    return tuple(values)


def parse_size(text: str) -> tuple[int, int, int]:
    """--synthetic N (an N³ cube) or NXxNYxNZ as (nx, ny, nz)."""
    try:
        parts = [int(p) for p in text.lower().split("x")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts *= 3
    if len(parts) != 3 or min(parts) < 1 or max(parts) > MAX_SIDE:
        raise InvalidParameterError(
            f"--synthetic {text!r} must be N or NXxNYxNZ with sides 1 to {MAX_SIDE}, "
            "e.g. --synthetic 128 or --synthetic 128x128x64"
        )
    return parts[0], parts[1], parts[2]


def default_workers(most: int) -> tuple[int, ...]:
    """1, 2, 4, ... up to `most`, and `most` itself."""
    counts = {1 << k for k in range(most.bit_length()) if 1 << k <= most}
    return tuple(sorted(counts | {most}))


def resolve_devices(text: str | None) -> list[DeviceInfo]:
    """The devices of --devices: none given, the chosen one (CHRONOCL_DEVICE or the default);
    'all', every OpenCL device that can build kernels; else a comma list of indices or name
    parts."""
    if not text:
        return [pick_device(None)[0]]
    if text.strip().lower() == "all":
        every = list_devices()
        if not every:
            raise EngineUnavailableError(NO_PLATFORM)
        found = usable_devices()
        if not found:
            raise no_build_error(every)
        return found
    chosen: dict[str, DeviceInfo] = {}
    for part in text.split(","):
        info = pick_device(part.strip() or "?")  # an empty part names no device
        chosen.setdefault(info[0].index, info[0])
    return list(chosen.values())


def check_matrix(volume_zyx: Sequence[int], n_steps: int, windows, workers) -> int:
    """Check windows and workers against the volume; returns the weak-scaling rows per worker."""
    if windows[-1] > n_steps:
        raise InvalidParameterError(
            f"--windows asks for {windows[-1]} steps but the series has {n_steps}; "
            f"use windows of at most {n_steps} steps"
        )
    unit = volume_zyx[0] // workers[-1]
    if unit < 1:
        raise InvalidParameterError(
            f"weak scaling gives each of {workers[-1]} workers Z // workers rows, and the volume "
            f"has only {volume_zyx[0]} z-rows; use --workers up to {volume_zyx[0]} or a "
            "larger volume"
        )
    return unit


# -- data -------------------------------------------------------------------------------------
def make_synthetic(
    folder: Path, size_xyz: Sequence[int], steps: int, progress: bool = False
) -> TimeSeries:
    """`steps` steps of the vortex data set at `size_xyz`, written to folder/synthetic.zarr."""
    nx, ny, nz = size_xyz
    return write_series(
        folder / "synthetic.zarr",
        synthetic.steps("vortex", steps, (nz, ny, nx)),
        n_steps=steps,
        volume_shape=(nz, ny, nx),
        dtype="float32",
        source=f"synthetic vortex {nx}x{ny}x{nz}, {steps} steps",
        progress=progress,
        levels=False,
    )


def crop_rows(series: TimeSeries, rows: int, steps: int, path: Path) -> TimeSeries:
    """The first `rows` z-rows of the first `steps` steps of `series` as a store at `path`
    (`series` itself when that is all its rows)."""
    if rows == series.volume_shape[0]:
        return series
    _, ny, nx = series.volume_shape
    return write_series(
        path,
        (series.read([t], 0, rows)[0] for t in range(steps)),
        n_steps=steps,
        volume_shape=(rows, ny, nx),
        dtype=series.dtype,
        source=f"z-rows 0:{rows} of {series.path}",
        levels=False,
    )


# -- the roofline -----------------------------------------------------------------------------
def roofline_at(store: str, window: int, devices: Sequence[str], repeats: int) -> dict:
    """Read rates where this runs: the window read from `store` (decoded, GB/s) and the
    in-memory read roofline on each device (`chronocl.engine.roofline`)."""
    series = open_series(store)
    where = distributed.worker_name()
    nz, ny, nx = series.volume_shape
    steps = list(range(window))
    rows = max(1, min(nz, ROOFLINE_BYTES // (window * ny * nx * series.dtype.itemsize)))
    times = race_times({"store": lambda: series.read_brick(steps, 0, rows)}, repeats)["store"]
    brick = series.read_brick(steps, 0, rows)
    store_s = statistics.median(times)
    return {
        "where": "bench process" if where == "local" else f"worker {where}",
        "window": window,
        "shape_zyx": [rows, ny, nx],
        "bytes": int(brick.nbytes),
        "store_read_gb_s": brick.nbytes / store_s / 1e9,
        "store_read_gvox_steps_s": brick.size / store_s / 1e9,
        "devices": {d: read_roofline(brick, d, repeats) for d in devices},
    }


# -- the matrix -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Cell:
    """One measurement: a study (strong or weak), device, worker count, window, series."""

    study: str
    device: str
    workers: int
    window: int
    series: TimeSeries


def plan_cells(
    full: TimeSeries, weak: dict[int, TimeSeries], windows, workers, devices
) -> list[Cell]:
    """Strong: every window, worker count and device on `full`. Weak: the largest window,
    every worker count and device on weak[n]."""
    cells = [Cell("strong", d, n, w, full) for d in devices for n in workers for w in windows]
    cells += [Cell("weak", d, n, windows[-1], weak[n]) for d in devices for n in workers]
    return cells


def time_cell(
    client, cell: Cell, addresses: Sequence[str], mode: str, repeats: int, scratch: Path, tick
) -> dict:
    """Time `cell` on the first `cell.workers` workers: one warm-up, then `repeats` runs
    (none: the warm-up alone, and an empty result)."""
    import dask

    series, window = cell.series, cell.window
    chosen = list(addresses[: cell.workers])
    nz, ny, nx = series.volume_shape
    voxel_steps = nz * ny * nx * window
    nbytes = voxel_steps * series.dtype.itemsize

    def once() -> float:
        out = scratch / f"out-{uuid.uuid4().hex[:8]}.zarr"
        t0 = time.perf_counter()
        with dask.annotate(workers=chosen, allow_other_workers=False):
            integrate_to_store(
                series, f"0:{window}", out, mode=mode, device=cell.device, client=client
            )
        took = time.perf_counter() - t0
        remove_path(out)
        tick(nbytes)
        return took

    once()  # builds the kernels on the workers, warms the file cache
    times = [once() for _ in range(repeats)]
    if not times:  # a warm-up alone
        return {}
    median = statistics.median(times)
    return {
        "study": cell.study,
        "device": cell.device,
        "workers": cell.workers,
        "window": window,
        "shape_zyx": [nz, ny, nx],
        "voxel_steps": voxel_steps,
        "bytes": nbytes,
        "times_s": times,
        "median_s": median,
        "min_s": min(times),
        "gvox_steps_s": voxel_steps / median / 1e9,
        "gb_s": nbytes / median / 1e9,
    }


@contextlib.contextmanager
def cluster(scheduler: str | None, workers: int) -> Iterator[tuple[object, list[str]]]:
    """(client, worker addresses): of the scheduler's cluster, or of a new LocalCluster of
    `workers` workers; at least `workers` of them, or one line saying so."""
    from distributed import Client

    with contextlib.ExitStack() as stack:
        if scheduler:
            client = stack.enter_context(
                contextlib.closing(distributed.connect_scheduler(scheduler))
            )
        else:
            local = stack.enter_context(distributed.local_cluster(workers))
            client = stack.enter_context(Client(local, set_as_default=False))
            client.wait_for_workers(workers)
        addresses = sorted(client.scheduler_info()["workers"])
        if len(addresses) < workers:
            raise InvalidParameterError(
                f"the cluster at {scheduler} has {len(addresses)} workers and --workers asks "
                f"for {workers}; use --workers up to {len(addresses)}"
            )
        yield client, addresses


def _version(package: str) -> str | None:
    try:
        return version(package)
    except PackageNotFoundError:
        return None


def machine() -> dict:
    """This machine and the software measured."""
    import dask
    import numpy as np

    return {
        "host": platform.node(),
        "system": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "chronocl": _version("chronocl"),
        "numpy": np.__version__,
        "dask": dask.__version__,
        "distributed": _version("distributed"),
        "pyopencl": _version("pyopencl"),
    }


def measure(
    client,
    addresses: Sequence[str],
    full: TimeSeries,
    weak: dict[int, TimeSeries],
    windows: Sequence[int],
    workers: Sequence[int],
    devices: Sequence[str],
    *,
    mode: str,
    repeats: int,
    scratch: Path,
    local: bool,
    advance: Callable[[int], None],
) -> tuple[list[dict], dict]:
    """(cells, roofline) of the whole matrix; `advance(window bytes)` after every run."""
    for device in devices:  # the workers import and build their kernels at once, untimed
        warm_up = Cell("warm-up", device, workers[-1], windows[0], full)
        time_cell(client, warm_up, addresses, mode, 0, scratch, advance)
    cells = plan_cells(full, weak, windows, workers, devices)
    done: dict[tuple, dict] = {}
    results = []
    for cell in cells:
        key = (cell.device, cell.workers, cell.window, cell.series.path)
        if key not in done:  # a weak cell on the whole volume is the strong cell
            done[key] = time_cell(client, cell, addresses, mode, repeats, scratch, advance)
        results.append({**done[key], "study": cell.study})
    args = (str(full.path), windows[-1], list(devices), repeats)
    if local:
        roofline = roofline_at(*args)
    else:
        roofline = client.submit(roofline_at, *args, workers=[addresses[0]], pure=False).result()
    return results, roofline


def runs_needed(volume_z: int, unit: int, windows, workers, devices, repeats: int) -> int:
    """How many timed and warm-up runs `measure` makes (for the progress bar)."""
    weak = sum(1 for n in workers if n * unit != volume_z)
    return len(devices) * ((len(windows) * len(workers) + weak) * (repeats + 1) + 1)
