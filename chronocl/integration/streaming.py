"""Integration larger than memory: z-slabs streamed from the series into a chronovolume store.

`integrate_to_store` reads (slab rows + gradient halo) x W x Y x X bricks of the window,
integrates them with the engine and writes each slab of the output zarr (the layout of
`Chronovolume.save`: ``rgba``, ``t_index``, attribute ``chronocl``) before reading further, so
memory is set by the budget (`--memory`), not by the data. Slabs are whole output chunks, so
no two slabs ever write the same chunk, and the same slab tasks run on a dask cluster
(`chronocl.integration.distributed`).

The output is built in a hidden sibling ``.NAME.partial-run`` and renamed into place when every
slab is written. Each finished slab leaves a marker in ``.chronocl-run/`` holding a hash of the
run's parameters; a re-run after a crash skips the slabs whose markers carry its own hash and
starts afresh when they do not. The running process holds a lock (``.chronocl-run/lock``):
a second run of the same output is refused while it lives, and once it is dead (killed) the
partial is resumed by the next streamed run or removed by the next write of NAME by any other
path (`chronocl.core.atomic.remove_stale`). A run that fails before any slab is finished, or on
bad input (a ChronoclError), removes its partial: nothing to resume. The commit moves the
partial to a name of its own process first, so that from then on any failure or kill leaves
nothing that outlives the next write.

Additive with ``normalize="max"`` needs the volume's maximum: the raw sums go to a temporary
array ``rgba_raw``, every slab marker records its maximum, and a second pass over the output
chunks writes ``rgba`` normalised (bit for bit as `reference.finalize` does for the whole
volume).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import shutil
import time
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path

import numpy as np
import zarr

from chronocl import reference
from chronocl.core import atomic
from chronocl.core.atomic import RUN_DIR, RUN_LOCK, lock_run, remove_path
from chronocl.core.budget import GrowthGuard, parse_memory
from chronocl.core.errors import (
    ChronoclError,
    InvalidParameterError,
    OutputBusyError,
    OutputExistsError,
    SlabTaskError,
)
from chronocl.core.memory import aligned_empty
from chronocl.core.paths import check_output
from chronocl.core.progress import meter
from chronocl.core.selection import Selection
from chronocl.data.bricks import Slab, slabs
from chronocl.data.chronovolume import FORMAT
from chronocl.data.series import STEPS_PER_READ, TimeSeries, compressors
from chronocl.engine import get_engine
from chronocl.integration.inmemory import Job, engine_rows, integrate_slabs, prepare
from chronocl.modes.spec import IntegrationSpec
from chronocl.reference import Partial

log = logging.getLogger("chronocl")


RUN_VERSION = 1
CHUNK_BYTES = 8 * 2**20  # output chunk size, as Chronovolume.save
BASE_BYTES = 2 * 2**20  # tables, small buffers and bookkeeping of one slab


# -- planning --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Plan:
    """Slabs of the output, all but the last `slab_rows` rows, each a whole number of chunks."""

    slabs: tuple[Slab, ...]
    slab_rows: int
    chunk_rows: int
    peak_bytes: int  # estimated memory held while one slab is integrated and written
    read_ahead: bool = True  # the next brick is read while this one is integrated
    steps_per_read: int = STEPS_PER_READ  # steps whose chunks are decoded at once


def stored_z_chunk(series: TimeSeries) -> int:
    """Rows per stored chunk along z (0 for in-memory data, which need no decoding)."""
    return series.z_chunk if getattr(series, "_zarr", None) is not None else 0


def needs_raw(spec: IntegrationSpec) -> bool:
    """Whether slabs are normalised in a second pass (additive by the volume's maximum)."""
    return spec.mode == "additive" and spec.normalize == "max"


def slab_bytes(
    job: Job,
    rows: int,
    engine: str,
    read_ahead: bool = True,
    write_behind: bool | None = None,
    steps_per_read: int = STEPS_PER_READ,
) -> int:
    """Memory held while a slab of `rows` output rows is read, integrated and written.

    Counts the brick being integrated and the one read ahead, one step's rows as the store
    returns them plus the stored chunks decoded at once for `steps_per_read` steps (compressed
    and decoded; at most zarr's async.concurrency), the engine's own work arrays (float64
    input goes to OpenCL as float32; the numpy reference works in float64), the slab's output
    and the previous one being written (write-behind; by default where there is read-ahead),
    and zarr's encoded copies while writing.
    """
    nz, ny, nx = job.series.volume_shape
    plane, w, item = ny * nx, job.selection.width, job.series.dtype.itemsize
    read_rows = min(nz, rows + 2 * job.halo)
    brick = read_rows * w * plane * item
    total = BASE_BYTES + brick * (2 if read_ahead else 1)
    zc = stored_z_chunk(job.series)
    if zc:
        # Stored chunks a read of these rows can touch: as many as they fill when a slab of
        # whole chunks without halo starts on a chunk, and one more where it may not.
        if rows % zc == 0 and job.halo == 0:
            touched = read_rows // zc
        else:
            touched = min(1 + math.ceil((read_rows - 1) / zc), math.ceil(nz / zc))
        # zarr decodes at most async.concurrency chunks of one call at once.
        in_flight = min(min(w, steps_per_read) * touched, zarr.config.get("async.concurrency"))
        total += 2 * in_flight * zc * plane * item
    total += read_rows * plane * item
    if engine == "numpy":
        # u (float32) and the reference's float64 RGBA, colour, gradients and temporaries
        total += read_rows * w * plane * 4 + read_rows * plane * 8 * 24
    elif job.series.dtype == np.float64:
        total += read_rows * w * plane * 4
    out = rows * plane * (16 + (4 if job.spec.has_t_index else 0))
    # The slab integrated, the one being written behind it, and zarr's encoded copies.
    behind = read_ahead if write_behind is None else write_behind
    total += (2 if behind else 1) * out + 2 * out
    if engine == "numpy" and job.spec.mode == "additive":
        total += rows * plane * 16 * 3  # reference.finalize's copies
    return total


# (steps decoded at once, read-ahead) from fastest to leanest: on two cores 8 steps per read
# streamed 1.1x faster than 4 with read-ahead, which was 1.15x faster than 2.
READ_OPTIONS = ((8, True), (8, False), (4, True), (4, False), (2, True), (2, False), (1, False))


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
    ahead. (The local run writes behind; a task on a cluster does neither:
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


def _most_rows(need, option: tuple[int, bool], top: int, budget: int) -> int:
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


# -- the run's store and its markers ----------------------------------------------------------
def run_hash(job: Job, engine: str, chunk_rows: int, compressor: str) -> str:
    """A hash of everything that decides the output's bytes: a marker is valid only under it."""
    s = job.series
    identity = {
        "version": RUN_VERSION,
        "store": str(Path(s.path).resolve()) if s.path else "",
        "source": s.source,
        "shape": list(s.shape),
        "dtype": str(s.dtype),
        "stats": [s.stats.vmin, s.stats.vmax, s.stats.step_min, s.stats.step_max],
        "means": list(s.stats.step_mean),
        "steps": list(job.selection.steps),
        "spec": job.spec.to_dict(),
        "value_range": [float(v) for v in job.value_range],
        "engine": engine,
        "chunk_rows": chunk_rows,
        "compressor": compressor,
    }
    text = json.dumps(identity, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def partial_path(target: Path) -> Path:
    """The hidden sibling where a run builds `target` (kept across crashes to resume)."""
    return target.parent / f".{target.name}.partial-run"


def target_of(tmp: Path) -> Path:
    """The output whose run builds at `tmp` (the inverse of `partial_path`)."""
    return tmp.parent / tmp.name[1 : -len(".partial-run")]


def open_run(tmp: Path, job: Job, plan: Plan, digest: str, compressor: str) -> int:
    """Lock the run's store at `tmp` and keep it when it belongs to the same run (resume), or
    make it afresh; returns the lock's file descriptor (closing it releases the run).

    Raises OutputBusyError while another live process holds the run. A fresh store is built
    under a name of this process and renamed to `tmp` complete with its lock, so `tmp` never
    exists without one.
    """
    for _ in range(3):
        try:
            fd = lock_run(tmp)
        except BlockingIOError:
            raise OutputBusyError(
                f"another chronocl process is writing {str(target_of(tmp))!r} "
                f"(its partial {tmp.name} is locked); wait for it to finish, or write "
                "another output"
            ) from None
        if fd is not None and _run_hash(tmp) == digest:
            return fd
        if fd is not None or os.path.lexists(tmp):
            log.info("discarding %s: it was made by a run with other parameters", tmp)
            _discard(tmp, fd)
        fd = _create_run(tmp, job, plan, digest, compressor)
        if fd is not None:
            return fd
    raise OutputBusyError(  # pragma: no cover - three runs racing for one output
        f"other chronocl processes keep making {tmp.name}; run one at a time"
    )


def _run_hash(tmp: Path) -> str | None:
    try:
        return json.loads((tmp / RUN_DIR / "run.json").read_text())["hash"]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _discard(tmp: Path, fd: int | None) -> None:
    """Remove the run at `tmp` (locked by `fd`, or made before locks)."""
    atomic.discard_run(tmp, target_of(tmp), fd)


def _create_run(tmp: Path, job: Job, plan: Plan, digest: str, compressor: str) -> int | None:
    """Build an empty run store with its lock taken, and move it to `tmp`; its lock fd, or
    None when another process made `tmp` meanwhile."""
    nz, ny, nx = job.series.volume_shape
    c = plan.chunk_rows
    codecs = compressors(compressor)
    build = atomic.partial_path(target_of(tmp))  # this process's: no one else removes it
    fd = None
    try:
        group = zarr.open_group(store=str(build), mode="w", zarr_format=3)
        names = ["rgba_raw", "rgba"] if needs_raw(job.spec) else ["rgba"]
        for name in names:
            group.create_array(
                name,
                shape=(nz, ny, nx, 4),
                chunks=(c, ny, nx, 4),
                dtype=np.float32,
                compressors=codecs,
            )
        if job.spec.has_t_index:
            group.create_array(
                "t_index",
                shape=(nz, ny, nx),
                chunks=(c, ny, nx),
                dtype=np.int32,
                compressors=codecs,
            )
        (build / RUN_DIR).mkdir()
        (build / RUN_DIR / RUN_LOCK).write_text(str(os.getpid()))
        fd = lock_run(build)  # a fresh file in a folder only this process knows: free
        _write_json(build / RUN_DIR / "run.json", {"hash": digest, "chunk_rows": c})
        if not atomic.rename_new(build, tmp):
            os.close(fd)
            remove_path(build)
            return None
    except BaseException:
        if fd is not None:
            os.close(fd)
        remove_path(build)
        raise
    return fd


def _marker(tmp: Path, kind: str, z0: int, z1: int) -> Path:
    return tmp / RUN_DIR / f"{kind}-{z0:07d}-{z1:07d}.json"


def mark_done(tmp: Path, kind: str, slab: Slab, digest: str, **info: object) -> None:
    """Record that `slab` is written (after its data: a marker never precedes its chunks)."""
    _write_json(_marker(tmp, kind, slab.z0, slab.z1), {"hash": digest, **info})


def done_slabs(tmp: Path, kind: str, digest: str) -> dict[tuple[int, int], dict]:
    """{(z0, z1): marker} of the slabs this run (same hash) finished before."""
    found = {}
    for path in (tmp / RUN_DIR).glob(f"{kind}-*.json"):
        try:
            info = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if info.get("hash") == digest:
            _, z0, z1 = path.stem.split("-")
            found[(int(z0), int(z1))] = info
    return found


def _write_json(path: Path, obj: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    part = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    part.write_text(json.dumps(obj))
    os.replace(part, path)


# -- one slab ---------------------------------------------------------------------------------
def output_array(group: zarr.Group, name: str) -> zarr.Array:
    """The output array `name` of a run's store, opened for writing whole chunks.

    Every chunk is written, empty or not, so that a missing chunk always means damage (the
    store says ``chunks: complete``); zarr's test for empty chunks would also scan each chunk
    again, costing as much as the write itself. This is a runtime setting of the opened array,
    not stored with it.
    """
    arr = group[name]
    return arr.with_config({"write_empty_chunks": True})  # type: ignore[union-attr]


def write_slab(group: zarr.Group, job: Job, slab: Slab, partial: Partial, final: bool) -> float:
    """Write one integrated slab; returns its largest colour value (for normalize="max")."""
    raw = needs_raw(job.spec)
    rgba = partial.rgba
    if not final and not raw:  # per-voxel finalisation (the numpy engine leaves it to us)
        rgba = reference.finalize(partial, job.positions, job.spec)
    output_array(group, "rgba_raw" if raw else "rgba")[slab.z0 : slab.z1] = rgba
    if partial.t_index is not None:
        output_array(group, "t_index")[slab.z0 : slab.z1] = partial.t_index
    return float(rgba[..., :3].max()) if raw else 0.0


def normalize_slab(group: zarr.Group, slab: Slab, chunk_rows: int, peak: float) -> None:
    """Second pass of additive/max: rgba = raw sums scaled by the volume maximum, per chunk."""
    for c0 in range(slab.z0, slab.z1, chunk_rows):
        c1 = min(c0 + chunk_rows, slab.z1)
        raw = np.asarray(group["rgba_raw"][c0:c1])
        output_array(group, "rgba")[c0:c1] = scale_by_peak(raw, peak)


def scale_by_peak(rgba: np.ndarray, peak: float) -> np.ndarray:
    """reference.finalize's max normalisation with the volume's maximum given (same float32 ops)."""
    return reference.finalize_sums(rgba, np.full(3, np.float32(peak)))


# -- what travels to a worker -----------------------------------------------------------------
def job_to_dict(job: Job) -> dict:
    """The small, picklable description of a job a worker rebuilds with `job_from_dict`."""
    if job.series.path is None:
        raise InvalidParameterError(
            "distributed integration reads the series from its store on every worker; "
            "save it first (series.save('data.zarr')) and open it with chronocl.open"
        )
    return {
        "store": str(job.series.path),
        "steps": list(job.selection.steps),
        "n_steps": job.selection.n_steps,
        "spec": job.spec.to_dict(),
        "value_range": [float(v) for v in job.value_range],
    }


def job_from_dict(d: dict, series: TimeSeries) -> Job:
    selection = Selection(tuple(d["steps"]), int(d["n_steps"]))
    value_range = (float(d["value_range"][0]), float(d["value_range"][1]))
    return Job.of(series, selection, IntegrationSpec.from_dict(d["spec"]), value_range)


# -- the call ---------------------------------------------------------------------------------
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
    **spec_args: object,
) -> Path:
    """Integrate the window of `series` slab by slab into the chronovolume store `out_path`.

    Arguments as `chronocl.integrate` (mode= and the make_spec arguments, or spec=), plus
    `memory`, the budget ('2GB', '512MiB', bytes; default 2GB) that sets the slab size
    (per worker with a client), `slab`, at most this many rows per slab, and `client`, a
    dask.distributed Client that runs one task per slab on its workers (see
    `chronocl.integration.distributed`). `compressor` compresses the output chunks:
    blosc-lz4 (default; as small as zstd here and about twice as fast to write), zstd (as
    `Chronovolume.save`)
    or none. A run interrupted or failed (other than on bad input) leaves its finished slabs
    behind; running it again with the same parameters resumes. Returns the path written;
    `Chronovolume.load` reads it.
    """
    from chronocl.core.paths import check_apart

    check_apart(out_path, [series.path])  # never onto, into or around the input
    target = check_output(out_path, overwrite)
    name = str(target).lower().rstrip("/")
    if not name.endswith(".zarr") or name.endswith(".ome.zarr"):
        raise InvalidParameterError(
            f"streamed output {str(target)!r} must be a chronocl .zarr store; "
            "convert it afterwards, or give a larger --memory to write .vti / .ome.zarr"
        )
    if engine not in ("opencl", "numpy"):
        raise InvalidParameterError(f"unknown engine {engine!r}; choose opencl or numpy")
    mode = str(spec_args.pop("mode", "alpha"))
    job = prepare(series, window, mode, spec, spec_args)
    budget = parse_memory(memory)
    if client is None:
        eng = get_engine(engine, device)
        plan = plan_slabs(job, budget, engine, engine_rows(eng, job), slab)
    else:
        from chronocl.integration.distributed import slab_rows_for

        rows = slab_rows_for(client, job.series.volume_shape[0])
        plan = plan_slabs(job, budget, engine, rows, slab, read_ahead=False)
    compressors(compressor)  # an unknown name fails before any work
    digest = run_hash(job, engine, plan.chunk_rows, compressor)
    tmp = partial_path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    lock = open_run(tmp, job, plan, digest, compressor)
    try:
        _run(
            job,
            plan,
            tmp,
            digest,
            engine,
            device,
            client,
            progress,
            eng if client is None else None,
        )
        commit(tmp, target, job, engine, overwrite)
    except BaseException as exc:
        _drop_unless_resumable(tmp, digest, exc)
        raise
    finally:
        os.close(lock)
    return target


def _drop_unless_resumable(tmp: Path, digest: str, exc: BaseException) -> None:
    """After a failure: keep the run at `tmp` only if a re-run can resume it.

    Kept: finished slabs after an interruption, an I/O or engine failure, lost workers, or
    an output that appeared meanwhile (a re-run with --overwrite resumes). Removed: a run
    with no finished slab, and one that chronocl itself stopped because the input or the
    parameters are wrong (any other ChronoclError: a damaged or changed store, bad values),
    which the same re-run would meet again.
    """
    kept = (SlabTaskError, OutputExistsError)  # lost workers; an output that appeared
    resumable = not isinstance(exc, ChronoclError) or isinstance(exc, kept)
    try:
        if not resumable or not done_slabs(tmp, "slab", digest):
            remove_path(tmp)
    except OSError as err:  # pragma: no cover - the failure itself is what is reported
        log.warning("could not check %s for finished slabs: %s", tmp, err)


def _run(job, plan, tmp, digest, engine, device, client, progress, eng) -> None:
    """Integrate the slabs not yet done (and normalise them for additive/max) into `tmp`."""
    done = done_slabs(tmp, "slab", digest)
    todo = [s for s in plan.slabs if (s.z0, s.z1) not in done]
    if done:
        log.info(
            "resuming %s: %d of %d slabs already written",
            target_of(tmp),
            len(done),
            len(plan.slabs),
        )

    if client is not None:
        from chronocl.integration.distributed import run_slab_tasks

        run_slab_tasks(client, job, plan, tmp, digest, todo, engine, device, progress)
    else:
        _run_local(job, eng, plan, tmp, digest, todo, len(plan.slabs) - len(todo), progress)

    if needs_raw(job.spec):
        markers = done_slabs(tmp, "slab", digest)
        peak = max(float(markers[(s.z0, s.z1)]["max"]) for s in plan.slabs)
        finished = done_slabs(tmp, "norm", digest)
        rest = [s for s in plan.slabs if (s.z0, s.z1) not in finished]
        if client is not None:
            from chronocl.integration.distributed import run_normalize_tasks

            run_normalize_tasks(client, plan, tmp, digest, rest, peak, progress)
        else:
            group = zarr.open_group(store=str(tmp), mode="r+")
            with meter(len(plan.slabs), "normalising", progress, len(finished)) as advance:
                for s in rest:
                    normalize_slab(group, s, plan.chunk_rows, peak)
                    mark_done(tmp, "norm", s, digest)
                    advance((s.z1 - s.z0) * _plane_bytes(job))


def _plane_bytes(job: Job) -> int:
    _, ny, nx = job.series.volume_shape
    return ny * nx * 16


def _run_local(
    job: Job,
    eng: object,
    plan: Plan,
    tmp: Path,
    digest: str,
    todo: Sequence[Slab],
    done: int,
    progress: bool,
) -> None:
    """Integrate `todo` here: read ahead on one thread, write behind on another."""
    _, ny, nx = job.series.volume_shape
    rows = plan.slab_rows
    guard = GrowthGuard(plan.peak_bytes)  # before the buffers, which the plan counts
    buffers = [
        (
            aligned_empty((rows, ny, nx, 4), np.float32),
            aligned_empty((rows, ny, nx), np.int32) if job.spec.has_t_index else None,
        )
        for _ in range(2)
    ]
    writes: list[Future | None] = [None, None]
    count = 0

    def out(s: Slab) -> tuple[np.ndarray, np.ndarray | None]:
        nonlocal count
        k, count = count % 2, count + 1
        if writes[k] is not None:
            writes[k].result()  # the slab before last has left this buffer
        rgba, t_index = buffers[k]
        n = s.z1 - s.z0  # a leading-axis prefix of a C-contiguous buffer is contiguous
        return rgba[:n], None if t_index is None else t_index[:n]

    group = zarr.open_group(store=str(tmp), mode="r+")
    with (
        meter(len(plan.slabs), "integrating slabs", progress, done) as advance,
        ThreadPoolExecutor(max_workers=1, thread_name_prefix="chronocl-write") as writer,
    ):

        def finish(s: Slab, partial: Partial, final: bool, t0: float) -> None:
            peak = write_slab(group, job, s, partial, final)
            guard.check()
            mark_done(tmp, "slab", s, digest, max=peak, seconds=time.perf_counter() - t0)
            advance((s.r1 - s.r0) * job.row_bytes)

        t0 = time.perf_counter()
        n = 2 if plan.read_ahead else 1
        brick_rows = plan.slab_rows + 2 * job.halo
        reader = BrickReader(job.series, brick_rows, job.selection.width, n, plan.steps_per_read)
        results = integrate_slabs(job, eng, todo, out, reader.read, plan.read_ahead)
        for i, (s, partial, final) in enumerate(results):
            writes[i % 2] = writer.submit(finish, s, partial, final, t0)
            t0 = time.perf_counter()
        for w in writes:
            if w is not None:
                w.result()


class BrickReader:
    """Reads bricks into reused buffers, in turn (fresh pages cost as much as reading): two
    where the next brick is read while one is integrated, or a list given.

    zarr decodes the rows straight into the brick (`TimeSeries.read_brick`); in-memory series
    get a fresh brick per read.
    """

    def __init__(
        self,
        series: TimeSeries,
        rows: int,
        width: int,
        buffers: list | int = 2,
        per_call: int = STEPS_PER_READ,
    ) -> None:
        self.series = series
        self.per_call = per_call
        self.arr = getattr(series, "_zarr", None)
        _, ny, nx = series.volume_shape
        shape = (min(rows, series.volume_shape[0]), width, ny, nx)
        if isinstance(buffers, int):
            n = buffers if self.arr else 0
            buffers = [aligned_empty(shape, series.dtype) for _ in range(n)]
        self.buffers = buffers
        self.turn = 0

    def read(self, steps: Sequence[int], r0: int, r1: int) -> np.ndarray:
        if self.arr is None:
            return self.series.read_brick(steps, r0, r1)
        brick = self.buffers[self.turn][: r1 - r0]
        self.turn = (self.turn + 1) % len(self.buffers)
        return self.series.read_brick(steps, r0, r1, out=brick, per_call=self.per_call)


def commit(tmp: Path, target: Path, job: Job, engine: str, overwrite: bool) -> None:
    """Finish the store (metadata, drop the raw sums and markers) and move it into place.

    The finished run is first moved to a name of this process (it can no longer resume), so
    whatever fails or kills the rest leaves nothing that outlives the next write of `target`;
    a failure removes it.
    """
    group = zarr.open_group(store=str(tmp), mode="r+")
    if "rgba_raw" in group:
        del group["rgba_raw"]
    group.attrs["chronocl"] = {
        "format": FORMAT,
        "version": 1,
        "chunks": "complete",
        **job.metadata(engine),
    }
    check_output(target, overwrite)
    final = atomic.partial_path(target)
    os.replace(tmp, final)
    try:
        shutil.rmtree(final / RUN_DIR)
        atomic.replace(final, target)
    except BaseException:
        remove_path(final)
        raise
