"""The plan of an out-of-core run: z-slabs of the output sized to a memory budget.

A slab is read (with its gradient halo), integrated and written before the next one is
read, so memory is set by the budget (`--memory`), not by the data. `slab_bytes` counts what
one slab holds; `plan_slabs` takes the largest slabs that fit, each a whole number of output
chunks (no two slabs ever write one chunk), choosing how many steps are decoded at once and
whether the next brick is read ahead. `fits_in_memory` says when no streaming is needed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from operator import itemgetter

import numpy as np
import zarr

from chronocl.core import env, host_threads
from chronocl.core.errors import InvalidParameterError
from chronocl.core.tuning import TUNING
from chronocl.data.bricks import Slab, slabs, stored_z_chunk
from chronocl.integration.inmemory import Job

CHUNK_BYTES = 8 * 2**20  # output chunk size, as Chronovolume.save

# (steps decoded at once, read-ahead) from fastest to leanest: on two cores 8 steps per read
# streamed 1.1x faster than 4 with read-ahead, which was 1.15x faster than 2.
READ_OPTIONS = ((8, True), (8, False), (4, True), (4, False), (2, True), (2, False), (1, False))


@dataclass(frozen=True)
class Plan:
    """Slabs of the output, all but the last `slab_rows` rows, each a whole number of chunks."""

    slabs: tuple[Slab, ...]
    slab_rows: int
    chunk_rows: int
    peak_bytes: int  # estimated memory held while one slab is integrated and written
    read_ahead: bool = True  # the next brick is read while this one is integrated
    # steps whose chunks are decoded at once
    steps_per_read: int = field(default_factory=lambda: TUNING.steps_per_read)


def run_threads() -> int:
    """Threads an out-of-core run may have working at once: chronocl's host threads, zarr's
    decode and encode threads and PoCL's (one per compute unit: the cores, or as forced by
    POCL_MAX_PTHREAD_COUNT / POCL_CPU_MAX_CU_COUNT; a GPU's driver has fewer)."""
    cores = os.cpu_count() or 1
    zarr_threads = zarr.config.get("threading.max_workers") or min(32, cores + 4)
    pocl = env.get("POCL_MAX_PTHREAD_COUNT") or env.get("POCL_CPU_MAX_CU_COUNT")
    device = int(pocl) if pocl.isdigit() else cores
    return host_threads.workers() + int(zarr_threads) + device


def slab_bytes(
    job: Job,
    rows: int,
    engine: str,
    read_ahead: bool = True,
    write_behind: bool | None = None,
    steps_per_read: int | None = None,  # None: TUNING.steps_per_read
) -> int:
    """Memory held while a slab of `rows` output rows is read, integrated and written.

    Counts the brick being integrated and the one read ahead, one step's rows as the store
    returns them plus the stored chunks decoded at once for `steps_per_read` steps (compressed and
    decoded; at most zarr's async.concurrency), the engine's own work arrays (float64 input goes to
    OpenCL as float32; the numpy reference works in float64), the slab's output and the previous one
    being written (write-behind; by default where there is read-ahead), and zarr's encoded copies
    while writing, and TUNING.run_thread_bytes for each of the run's threads (`run_threads()`), so
    that the budget holds at any thread count.
    """
    steps_per_read = TUNING.steps_per_read if steps_per_read is None else steps_per_read
    nz, ny, nx = job.series.volume_shape
    plane, w, item = ny * nx, job.selection.width, job.series.dtype.itemsize
    read_rows = min(nz, rows + 2 * job.halo)
    brick = read_rows * w * plane * item
    total = TUNING.run_base_bytes + brick * (2 if read_ahead else 1)
    total += TUNING.run_thread_bytes * run_threads()
    zc = stored_z_chunk(job.series)
    if zc:
        # Stored chunks a read of these rows can touch: as many as they fill when a slab of
        # whole chunks without halo starts on a chunk, and one more where it may not.
        if rows % zc == 0 and job.halo == 0:
            touched = read_rows // zc
        else:
            touched = min(1 + math.ceil((read_rows - 1) / zc), math.ceil(nz / zc))
        # zarr decodes at most async.concurrency chunks of one call at once; a store decoded
        # directly (`chronocl.data.chunk_reads`), one chunk per host thread.
        in_flight = min(min(w, steps_per_read) * touched, zarr.config.get("async.concurrency"))
        in_flight = max(in_flight, min(w * touched, host_threads.workers()))
        total += 2 * in_flight * zc * plane * item
    total += read_rows * plane * item
    if engine == "numpy":
        # u (float32) and the reference's float64 RGBA, colour, gradients and temporaries
        total += read_rows * w * plane * 4 + read_rows * plane * 8 * 24
        total += rows * plane * 16 * 3  # a finalize's copies of the slab (float64 in, float32)
    elif job.series.dtype == np.float64:
        total += read_rows * w * plane * 4
    out = rows * plane * (16 + (4 if job.spec.has_t_index else 0))
    # The slab integrated, the one being written behind it, and zarr's encoded copies.
    behind = read_ahead if write_behind is None else write_behind
    total += (2 if behind else 1) * out + 2 * out
    return total


def plan_slabs(
    job: Job,
    budget: int,
    engine: str,
    max_rows: int | None = None,
    slab: int | None = None,
    read_ahead: bool = True,
) -> Plan:
    """The largest slabs that fit `budget` (and the engine's `max_rows`, and `slab` if given).

    From a store, slabs of whole stored chunks come first, since a chunk two slabs share is
    decoded twice; then as many steps decoded at once as fit, then reading the next brick
    ahead. (The local executor writes behind; a task on a cluster does neither:
    `read_ahead=False`.) With a gradient halo slabs share chunks anyway, and the plan takes
    the most rows any option allows. Data in memory are not decoded: the most rows with
    read-ahead, or without where that alone fits.
    """
    nz, ny, nx = job.series.volume_shape
    behind = read_ahead
    options = [o for o in READ_OPTIONS if read_ahead or not o[1]]

    def need(rows: int, option: tuple[int, bool]) -> int:
        return slab_bytes(job, rows, engine, option[1], behind, option[0])

    least = need(1, options[-1])
    if least > budget:
        mb = math.ceil(least / 1e6)
        raise InvalidParameterError(
            f"memory budget {budget / 1e6:.0f} MB is too small: integrating a "
            f"{job.selection.width}-step window of {nx}x{ny} one z-row at a time needs at "
            f"least {mb} MB; use --memory {mb}MB or more"
        )
    top = min(nz, max_rows or nz, slab or nz)
    zc = stored_z_chunk(job.series)
    cap = max(1, CHUNK_BYTES // (ny * nx * 16))  # output chunk rows
    choice = None
    if zc and job.halo == 0:
        # Whole stored chunks need less memory than a misaligned slab of nearly the same size.
        whole = [k * zc for k in range(1, top // zc + 1)]
        for option in options:
            fit = [n for n in whole if need(n, option) <= budget]
            if fit:
                rows = fit[-1]  # output chunks that divide it keep every slab whole chunks
                chunk = max(d for d in range(1, min(cap, rows) + 1) if rows % d == 0)
                choice = rows, chunk, option
                break
    if choice is None:
        if not zc:  # nothing to decode: keep the read-ahead while one row fits with it
            options = [o for o in options[:2] if need(1, o) <= budget][:1]
        # The most rows any option allows (every row fewer decodes more), the fastest of equals.
        fits = [(_most_rows(need, o, top, budget), o) for o in options]
        most, option = max(fits, key=itemgetter(0))
        chunk = max(1, min(nz, cap, most))
        choice = most // chunk * chunk, chunk, option
    rows, chunk, (per_read, ahead) = choice
    peak = slab_bytes(job, rows, engine, ahead, behind, per_read)
    return Plan(tuple(slabs(nz, rows, job.halo)), rows, chunk, peak, ahead, per_read)


def _most_rows(
    need: Callable[[int, tuple[int, bool]], int], option: tuple[int, bool], top: int, budget: int
) -> int:
    """The largest rows <= top with need(rows, option) <= budget (0 if not even one)."""
    low, high = 0, top
    while low < high:
        mid = (low + high + 1) // 2
        low, high = (mid, high) if need(mid, option) <= budget else (low, mid - 1)
    return low


def fits_in_memory(job: Job, budget: int, engine: str = "opencl") -> bool:
    """Whether the whole window's brick and the output fit `budget` (else stream)."""
    nz = job.series.volume_shape[0]
    return slab_bytes(job, nz, engine, read_ahead=False) <= budget
