"""The store an out-of-core run builds, its slab markers, and the commit that finishes it.

The output is built in a hidden sibling ``.NAME.partial-run`` (the layout of
`Chronovolume.save`: ``rgba``, ``t_index``, attribute ``chronocl``) and renamed into place
when every slab is written. Each finished slab leaves a marker in ``.chronocl-run/`` holding
a hash of the run's parameters; a re-run skips the slabs whose markers carry its own hash
and starts afresh when they do not. The running process holds a lock (``.chronocl-run/lock``):
a second run of the same output is refused while it lives, and once it is dead the partial
is resumed by the next streamed run or removed by the next write of NAME by any other path
(`chronocl.core.atomic.remove_stale`). The commit moves the partial to a name of its own
process first, so that from then on any failure or kill leaves nothing that outlives the
next write.

A mode whose finalisation is global (`IntegrationSpec.finalize_is_global`: a normalisation
by the volume's maximum) writes its raw partial to ``rgba_raw``; every slab marker
records the slab's per-channel maxima, and a second pass (`FinishTask`) finalises chunk by
chunk through `reference.finalize`, bit for bit as for the whole volume.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr

from chronocl import reference
from chronocl.core import atomic
from chronocl.core.atomic import RUN_DIR, RUN_LOCK, lock_run, remove_path
from chronocl.core.errors import ChronoclError, OutputBusyError, OutputExistsError, SlabTaskError
from chronocl.core.paths import check_output
from chronocl.data.bricks import Slab
from chronocl.data.chronovolume import FORMAT
from chronocl.data.writer import compressors
from chronocl.integration.inmemory import Job
from chronocl.integration.runs.plan import Plan
from chronocl.integration.window_centres import window_centres
from chronocl.modes.base import Partial
from chronocl.modes.spec import IntegrationSpec

log = logging.getLogger("chronocl")

RUN_VERSION = 2  # 2: markers of globally finalised runs hold per-channel maxima


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


# -- opening ----------------------------------------------------------------------------------
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
            atomic.discard_run(tmp, target_of(tmp), fd)
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
        names = ["rgba_raw", "rgba"] if job.spec.finalize_is_global else ["rgba"]
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


# -- markers ----------------------------------------------------------------------------------
def mark_done(tmp: Path, kind: str, slab: Slab, digest: str, **info: object) -> None:
    """Record that `slab` is written (after its data: a marker never precedes its chunks)."""
    name = f"{kind}-{slab.z0:07d}-{slab.z1:07d}.json"
    _write_json(tmp / RUN_DIR / name, {"hash": digest, **info})


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


# -- writing ----------------------------------------------------------------------------------
def output_array(group: zarr.Group, name: str) -> zarr.Array:
    """The output array `name` of a run's store, opened for writing whole chunks.

    Every chunk is written, empty or not, so that a missing chunk always means damage (the
    store says ``chunks: complete``); zarr's test for empty chunks would also scan each chunk
    again, costing as much as the write itself. This is a runtime setting of the opened array,
    not stored with it.
    """
    arr = group[name]
    return arr.with_config({"write_empty_chunks": True})  # type: ignore[union-attr]


def volume_maxima(tmp: Path, plan: Plan, digest: str) -> list[float]:
    """Per-channel maxima of the raw partial over every slab (from their markers)."""
    markers = done_slabs(tmp, "slab", digest)
    found = [markers[(s.z0, s.z1)]["maxima"] for s in plan.slabs]
    return [float(v) for v in np.max(np.asarray(found, np.float64), axis=0)]


@dataclass(frozen=True)
class FinishTask:
    """The second pass of a globally finalised run for one slab: `rgba` from ``rgba_raw``.

    Each chunk is finalised together with one voxel holding the volume's per-channel maxima,
    so that `reference.finalize` sees the volume's statistics (its maximum) and gives the
    chunk's voxels the bits it gives them in the whole volume. Small and picklable: a dask
    worker gets it as it is.
    """

    store: str
    digest: str
    chunk_rows: int
    maxima: tuple[float, ...]
    positions: tuple[float, ...]
    spec: dict

    def __call__(self, bounds: tuple[int, int, int, int]) -> dict:
        t0 = time.perf_counter()
        slab = Slab(*bounds)
        group = zarr.open_group(store=self.store, mode="r+")
        spec = IntegrationSpec.from_dict(self.spec)
        positions = np.asarray(self.positions, np.float64)
        witness = np.asarray(self.maxima, np.float32)[None]
        written = 0
        for c0 in range(slab.z0, slab.z1, self.chunk_rows):
            c1 = min(c0 + self.chunk_rows, slab.z1)
            raw = np.asarray(group["rgba_raw"][c0:c1])
            rgba = np.concatenate([raw.reshape(-1, 4), witness])
            done = reference.finalize(Partial(rgba, None), positions, spec)[:-1]
            output_array(group, "rgba")[c0:c1] = done.reshape(raw.shape)
            written += raw.nbytes
        mark_done(Path(self.store), "norm", slab, self.digest)
        return {"slab": slab.z0, "seconds": time.perf_counter() - t0, "bytes": written}


# -- finishing --------------------------------------------------------------------------------
def commit(tmp: Path, target: Path, job: Job, engine: str, overwrite: bool) -> None:
    """Finish the store (metadata, drop the raw partial and markers) and move it into place.

    The finished run is first moved to a name of this process (it can no longer resume), so
    whatever fails or kills the rest leaves nothing that outlives the next write of `target`;
    a failure removes it.
    """
    group = zarr.open_group(store=str(tmp), mode="r+")
    if "rgba_raw" in group:
        del group["rgba_raw"]
    centres = window_centres(job.series, job.selection, job.value_range)
    group.attrs["chronocl"] = {
        "format": FORMAT,
        "version": 1,
        "chunks": "complete",
        **job.metadata(engine),
        **({"centres": centres} if centres is not None else {}),  # the default view's
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


def drop_unless_resumable(tmp: Path, digest: str, exc: BaseException) -> None:
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
