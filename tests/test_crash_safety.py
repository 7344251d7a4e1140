"""Crash safety: `chronocl ingest`, streamed `integrate` and `export` killed with SIGKILL.

Each command runs as its own process and is killed (kill -9) at several points, found by
polling its hidden partial: after k chunk files (ingest), k finished slabs (streamed
integrate), k step files or k steps written (export .vti / .npy). After every kill:

- nothing half-written is at the target: no target, or, where --overwrite was replacing an
  existing output, that old output byte for byte;
- every file of the input is byte-identical;
- a hidden partial is there (the kill did land mid-write).

A rerun then completes with the output of a clean run (same bytes, or for a chronovolume the
same arrays and metadata), and once it has, no hidden partial of the target is left: not the
ones of the killed runs, whichever path the rerun takes (a streamed integrate rerun in memory
included). The killed runs are slowed down (a pause after each chunk or step they write, by
a shim around the real command line) so that the polling can catch them between writes.

In-process tests check the rest of the guarantee: failures (also of the final rename) leave
no partial, partials of dead writers go at the next commit, those of live writers stay, and a
live streamed run is neither removed nor run twice.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import chronocl
import chronocl.integration.runs.streaming as streaming
from chronocl.core import atomic
from chronocl.core.errors import InvalidDataError, OutputBusyError, OutputExistsError
from chronocl.data.formats.export import export_series
from chronocl.data.formats.raw import ingest_raw
from chronocl.data.series import write_series
from chronocl.integration.inmemory import prepare
from chronocl.integration.runs.streaming import integrate_to_store, partial_path

# The real command line, with every chunk written (zarr) and every step exported paused for
# CRASH_TEST_DELAY seconds, so that a poll sees the partial between two writes.
SHIM = r"""
import os, sys, time
delay = float(os.environ.get("CRASH_TEST_DELAY") or 0)
if delay:
    import zarr.storage
    import chronocl.data.formats.export as es
    _set, _read = zarr.storage.LocalStore.set, es._read_step
    async def slow_set(self, key, value, *args, **kwargs):
        await _set(self, key, value, *args, **kwargs)
        if not key.endswith("zarr.json"):
            time.sleep(delay)
    def slow_read(*args):
        step = _read(*args)
        time.sleep(delay)
        return step
    zarr.storage.LocalStore.set = slow_set
    es._read_step = slow_read
from chronocl.cli import main
sys.argv[0] = "chronocl"
main()
"""


# -- helpers ----------------------------------------------------------------------------------
def digest(path: Path) -> dict[str, str]:
    """sha256 of every file under `path` (or of the file), by path relative to it."""
    path = Path(path)
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return {str(f.relative_to(path)): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}


def hidden(folder: Path, name: str) -> list[Path]:
    """The hidden partials (and moved-aside old outputs) of `folder / name`."""
    return sorted(
        p
        for p in folder.iterdir()
        if p.name.startswith(f".{name}.partial-") or p.name.startswith(f".{name}.old-")
    )


def start(args, cwd: Path, delay: float = 0.0) -> subprocess.Popen:
    log = open(cwd / f"stderr-{time.monotonic_ns()}.txt", "w+")
    proc = subprocess.Popen(
        [sys.executable, "-c", SHIM, *map(str, args)],
        cwd=cwd,
        stdout=subprocess.DEVNULL,
        stderr=log,
        env={**os.environ, "CRASH_TEST_DELAY": str(delay)},
    )
    proc.log = log  # type: ignore[attr-defined]
    return proc


def stderr_of(proc: subprocess.Popen) -> str:
    proc.log.seek(0)  # type: ignore[attr-defined]
    return proc.log.read()  # type: ignore[attr-defined]


def run(args, cwd: Path) -> str:
    """Run the command to the end (no pause); its stderr. It must succeed."""
    proc = start(args, cwd)
    assert proc.wait(timeout=120) == 0, stderr_of(proc)
    return stderr_of(proc)


def count(predicate) -> int:
    try:
        return predicate()
    except (OSError, ValueError, EOFError):  # renamed, or not there (or its header) yet
        return 0


def kill_when(proc: subprocess.Popen, reached, timeout: float = 60.0) -> None:
    """Poll `reached(pid)` and SIGKILL `proc` as soon as it is true; it must still be running."""
    deadline = time.monotonic() + timeout
    while not count(lambda: reached(proc.pid)):
        assert proc.poll() is None, "finished before the kill point:\n" + stderr_of(proc)
        assert time.monotonic() < deadline, "kill point never reached:\n" + stderr_of(proc)
        time.sleep(0.002)
    os.kill(proc.pid, signal.SIGKILL)
    assert proc.wait(timeout=30) == -signal.SIGKILL, stderr_of(proc)


def files_under(folder: Path, pattern: str = "*") -> int:
    return sum(1 for p in folder.rglob(pattern) if p.is_file())


def the_partial(folder: Path, name: str, pid: int) -> Path:
    """The partial that process `pid` is writing."""
    found = [p for p in hidden(folder, name) if p.name.startswith(f".{name}.partial-{pid}-")]
    if not found:
        raise FileNotFoundError(name)
    return found[0]


def assert_after_kill(folder: Path, name: str, old: dict | None, inputs: dict) -> None:
    """Nothing half-written at the target, the input intact, the kill's partial left."""
    target = folder / name
    if old is None:
        assert not target.exists(), f"{target} appeared though the run was killed"
    else:
        assert digest(target) == old, f"{target} is not the old output any more"
    for path, before in inputs.items():
        assert digest(path) == before, f"input {path} changed"
    assert hidden(folder, name), "the kill left no partial: it did not land mid-write"


def assert_clean(folder: Path, name: str, inputs: dict) -> None:
    assert hidden(folder, name) == [], "a hidden partial was left behind"
    for path, before in inputs.items():
        assert digest(path) == before, f"input {path} changed"


# -- ingest -----------------------------------------------------------------------------------
NX, NY, NZ, STEPS = 24, 16, 12, 8


def raw_steps(folder: Path, seed: int) -> list[Path]:
    folder.mkdir()
    rng = np.random.default_rng(seed)
    files = []
    for t in range(STEPS):
        path = folder / f"v_{t}.raw"
        rng.random((NZ, NY, NX), dtype=np.float32).tofile(path)
        files.append(path)
    return files


def chunks(store: Path, pid: int) -> int:
    return files_under(the_partial(store.parent, store.name, pid) / "data" / "c")


def test_killed_ingest_leaves_nothing_and_the_rerun_is_a_clean_run(tmp_path):
    files = raw_steps(tmp_path / "raw", 1)
    clean = tmp_path / "clean" / "v.zarr"
    ingest_raw(files, clean, dims=(NX, NY, NZ), spacing=(1.0, 2.0, 3.0))  # (dx, dy, dz)
    assert files_under(clean / "data" / "c") == STEPS  # one chunk per step
    out = tmp_path / "v.zarr"
    ingest_raw(raw_steps(tmp_path / "old", 2), out, dims=(NX, NY, NZ))  # to be replaced
    old = digest(out)
    inputs = {f: digest(f) for f in files}
    cmd = ["ingest", tmp_path / "raw" / "v_*.raw", "-o", out, "--dims", NX, NY, NZ]
    cmd += ["--spacing", 1.0, 2.0, 3.0, "--overwrite"]

    # Killed after 2 chunks, then a second run killed after 5: two dead writers' partials,
    # and the old store intact.
    for k in (2, 5):
        proc = start(cmd, tmp_path, delay=0.1)
        kill_when(proc, lambda pid, k=k: chunks(out, pid) >= k)
        assert_after_kill(tmp_path, out.name, old, inputs)
    assert len(hidden(tmp_path, out.name)) == 2
    run(cmd, tmp_path)
    assert digest(out) == digest(clean)  # byte for byte the clean run's store
    assert_clean(tmp_path, out.name, inputs)


# -- streamed integrate -----------------------------------------------------------------------
WINDOW = "0:6"


@pytest.fixture(scope="module")
def series_store(tmp_path_factory):
    """6 steps of 24 x 12 x 16 (Z, Y, X), stored 4 rows per chunk."""
    rng = np.random.default_rng(5)
    data = rng.random((6, 24, 12, 16), dtype=np.float32)
    path = tmp_path_factory.mktemp("series") / "s.zarr"
    return write_series(
        path,
        iter(data),
        n_steps=6,
        volume_shape=data.shape[1:],
        dtype="float32",
        chunk_bytes=4 * 12 * 16 * 4,
    )


def assert_same_chronovolume(path: Path, ref: chronocl.Chronovolume) -> None:
    cv = chronocl.Chronovolume.load(path)
    assert cv.rgba.tobytes() == ref.rgba.tobytes()
    assert cv.t_index.tobytes() == ref.t_index.tobytes()
    assert cv.metadata == json.loads(json.dumps(ref.metadata))  # as stored: lists, not tuples
    assert cv.steps == ref.steps


def test_killed_streamed_integrate_resumes_or_is_replaced_in_memory(tmp_path, series_store):
    job = prepare(series_store, WINDOW, "max", None, {})
    budget = streaming.slab_bytes(job, 4, "numpy")
    plan = streaming.plan_slabs(job, budget, "numpy")
    n = len(plan.slabs)
    assert n == 6 and not streaming.fits_in_memory(job, budget, "numpy")
    ref = chronocl.integrate(series_store, WINDOW, "max", engine="numpy")
    clean = integrate_to_store(
        series_store, WINDOW, tmp_path / "clean.zarr", mode="max", engine="numpy", memory=budget
    )
    assert_same_chronovolume(clean, ref)
    inputs = {series_store.path: digest(series_store.path)}
    out = tmp_path / "cv.zarr"
    markers = partial_path(out) / streaming.RUN_DIR

    def finished() -> int:
        return len(list(markers.glob("slab-*.json")))

    def streamed(*more):
        base = ["integrate", series_store.path, out, "--mode", "max", "--window", WINDOW]
        return [*base, "--engine", "numpy", "--memory", budget, *more]

    # Killed after 1 slab; the rerun resumes and is killed after 3.
    for k in (1, 3):
        proc = start(streamed(), tmp_path, delay=0.15)
        kill_when(proc, lambda pid, k=k: finished() >= k)
        assert_after_kill(tmp_path, out.name, None, inputs)
    done = finished()
    assert 3 <= done < n
    note = run(streamed(), tmp_path)
    assert f"resuming {out}: {done} of {n} slabs already written" in note
    assert_same_chronovolume(out, ref)
    assert digest(out) == digest(clean)  # the streamed bytes, file for file
    assert_clean(tmp_path, out.name, inputs)

    # Replacing it (--overwrite), killed after 2 slabs; rerun in memory (a larger --memory).
    old = digest(out)
    proc = start(streamed("--overwrite"), tmp_path, delay=0.15)
    kill_when(proc, lambda pid: finished() >= 2)
    assert_after_kill(tmp_path, out.name, old, inputs)
    assert partial_path(out).exists()
    base = ["integrate", series_store.path, out, "--mode", "max", "--window", WINDOW]
    note = run([*base, "--engine", "numpy", "--memory", "1GB", "--overwrite"], tmp_path)
    assert "steps (0, 1, 2, 3, 4, 5)" in note  # in memory, not ", streamed"
    assert_same_chronovolume(out, ref)
    assert_clean(tmp_path, out.name, inputs)  # .cv.zarr.partial-run went with the commit


# -- export -----------------------------------------------------------------------------------
def vti_files(out: Path, pid: int) -> int:
    """.vti files in the partial folder of process `pid`."""
    return files_under(the_partial(out.parent, out.name, pid), "[!.]*.vti")


def npy_steps(out: Path, pid: int) -> int:
    """Steps written so far to the partial .npy of process `pid` (every value is >= 1)."""
    arr = np.load(the_partial(out.parent, out.name, pid), mmap_mode="r")
    return int((arr[:, -1, -1, -1] >= 1).sum())


@pytest.mark.parametrize("fmt", ["vti", "npy"])
def test_killed_export_leaves_nothing_and_the_rerun_is_a_clean_run(tmp_path, fmt):
    rng = np.random.default_rng(9)
    data = 1 + rng.random((8, 10, 6, 7), dtype=np.float32)
    store = tmp_path / "s.zarr"
    series = write_series(store, iter(data), n_steps=8, volume_shape=(10, 6, 7), dtype="float32")
    name = "steps" if fmt == "vti" else "steps.npy"
    clean = export_series(series, tmp_path / "clean" / name, fmt=fmt)[0].parent
    clean = clean if fmt == "vti" else tmp_path / "clean" / name
    out = tmp_path / name
    old = None  # .npy: a new output
    if fmt == "vti":  # an old export to be replaced
        export_series(series, out, fmt=fmt, window="0:3")
        old = digest(out)
    inputs = {store: digest(store)}
    cmd = ["export", store, "-o", out, "--format", fmt, "--overwrite"]
    written = vti_files if fmt == "vti" else npy_steps
    for k in (1, 4):  # two dead writers' partials
        proc = start(cmd, tmp_path, delay=0.1)
        kill_when(proc, lambda pid, k=k: written(out, pid) >= k)
        assert_after_kill(tmp_path, out.name, old, inputs)
    run(cmd, tmp_path)
    assert digest(out) == digest(clean)
    assert_clean(tmp_path, out.name, inputs)


# -- in process: failures, stale and live partials --------------------------------------------
def dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_commit_removes_dead_writers_partials_and_keeps_live_ones(tmp_path):
    out = tmp_path / "a.zarr"
    dead, live = dead_pid(), os.getppid()
    stale = [
        f".a.zarr.partial-{dead}-0123456789ab",  # a killed writer
        ".a.zarr.partial-deadbeef",  # a name from before pids
        f".a.zarr.old-{dead}-0123456789ab",  # an old output moved aside, then killed
        ".a.zarr.partial-run",  # a streamed run that holds no lock
    ]
    kept = [
        f".a.zarr.partial-{live}-0123456789ab",  # a live writer's
        f".a.zarr.partial-{os.getpid()}-0123456789ab",  # this process's
        f".ab.zarr.partial-{dead}-0123456789ab",  # another output's
        "a.zarr.partial-1-0123456789ab",  # not hidden: not ours
    ]
    for name in stale + kept:
        (tmp_path / name).mkdir()
    chronocl.TimeSeries.from_array(np.ones((2, 3, 4, 5), np.float32)).save(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*kept, "a.zarr"])


def test_a_locked_streamed_run_is_neither_removed_nor_run_twice(tmp_path, monkeypatch):
    series = chronocl.TimeSeries.from_array(np.random.default_rng(2).random((3, 8, 4, 5)))
    ref = chronocl.integrate(series, None, "max", engine="numpy")
    out = tmp_path / "cv.zarr"
    real, calls = streaming.write_slab, []

    def failing(group, job, slab, *rest):
        calls.append(slab.z0)
        if len(calls) > 2:
            raise RuntimeError("injected failure")
        return real(group, job, slab, *rest)

    monkeypatch.setattr(streaming, "write_slab", failing)
    with pytest.raises(RuntimeError, match="injected"):
        integrate_to_store(series, None, out, mode="max", slab=2, engine="numpy")
    run = partial_path(out)
    assert run.exists()  # slabs are finished: kept to resume
    monkeypatch.setattr(streaming, "write_slab", real)

    fd = atomic.lock_run(run)  # as a live process running it would
    assert fd is not None
    try:
        with pytest.raises(OutputBusyError, match="another chronocl process"):
            integrate_to_store(series, None, out, mode="max", slab=2, engine="numpy")
        ref.save(out)  # a commit of the same output by another path
        assert run.exists()  # a live run's partial stays
    finally:
        os.close(fd)

    calls.clear()
    monkeypatch.setattr(streaming, "write_slab", lambda *a: calls.append(a[2].z0) or real(*a))
    integrate_to_store(series, None, out, mode="max", slab=2, engine="numpy", overwrite=True)
    assert len(calls) == 2  # resumed: 2 of 4 slabs were finished
    assert_same_chronovolume(out, ref)
    assert hidden(tmp_path, out.name) == []


@pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")  # flat test data
def test_failures_leave_no_partial(tmp_path, monkeypatch):
    series = chronocl.TimeSeries.from_array(1 + np.zeros((3, 5, 4, 6), np.float32))
    # A .npy onto a folder (the final rename would fail): refused, nothing left.
    (tmp_path / "f.npy").mkdir()
    with pytest.raises(OutputExistsError, match="is a folder"):
        export_series(series, tmp_path / "f.npy", fmt="npy", overwrite=True)
    # Every rename failing: the error comes through, no partial stays.
    real = os.replace

    def failing(src, dst):
        if Path(dst).name in ("g.npy", "g", "h.zarr", "cv.zarr"):
            raise OSError(28, "No space left on device", str(dst))
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", failing)
    monkeypatch.setattr(atomic, "exchange", lambda a, b: False)
    monkeypatch.setattr(atomic, "rename_new", lambda a, b: failing(a, b))
    for fmt, name in (("npy", "g.npy"), ("vti", "g")):
        with pytest.raises(OSError, match="No space"):
            export_series(series, tmp_path / name, fmt=fmt)
    with pytest.raises(OSError, match="No space"):
        series.save(tmp_path / "h.zarr")
    with pytest.raises(OSError, match="No space"):
        integrate_to_store(series, None, tmp_path / "cv.zarr", slab=2, engine="numpy")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.npy"]


@pytest.mark.parametrize(
    ("after", "error", "kept"),
    [
        (0, RuntimeError, False),  # no slab finished: nothing to resume
        (2, RuntimeError, True),  # kept to resume
        (2, InvalidDataError, False),  # bad input: the same re-run would fail again
    ],
)
@pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")  # flat test data
def test_a_failed_streamed_run_keeps_its_partial_only_to_resume(
    tmp_path, monkeypatch, after, error, kept
):
    series = chronocl.TimeSeries.from_array(np.ones((3, 8, 4, 5), np.float32))
    real, calls = streaming.write_slab, []

    def failing(*args):
        calls.append(1)
        if len(calls) > after:
            raise error("injected failure")
        return real(*args)

    monkeypatch.setattr(streaming, "write_slab", failing)
    with pytest.raises(error, match="injected"):
        integrate_to_store(series, None, tmp_path / "cv.zarr", slab=2, engine="numpy")
    assert [p.name for p in tmp_path.iterdir()] == ([".cv.zarr.partial-run"] if kept else [])


def test_replacing_a_folder_without_an_exchange_moves_the_old_one_aside(tmp_path, monkeypatch):
    monkeypatch.setattr(atomic, "_renameat2", None)
    out = tmp_path / "s.zarr"
    for value in (1.0, 2.0):
        series = chronocl.TimeSeries.from_array(np.full((2, 3, 4, 5), value, np.float32))
        series.save(out, overwrite=True)
    assert chronocl.open(out).read([1])[0].max() == 2.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.zarr"]


@pytest.mark.parametrize("name", ["{s}", "{s}/cv.zarr", "{s}/cv.vti"])
def test_a_chronovolume_is_never_saved_over_or_into_the_series_it_came_from(tmp_path, name):
    """`Chronovolume.save` and `save_chronovolume` (the Python API's outputs, which the CLI's
    check before them) refuse the store a chronovolume was integrated from, or a path inside
    it, even with overwrite: the store once became the chronovolume, its series gone."""
    from chronocl.core.errors import OutputIsInputError
    from chronocl.data.formats.outputs import save_chronovolume

    data = np.random.default_rng(1).random((4, 3, 4, 5), dtype=np.float32)
    store = tmp_path / "s.zarr"
    chronocl.TimeSeries.from_array(data).save(store)
    before = digest(store)
    cv = chronocl.integrate(chronocl.open(store), "0:3", mode="max")
    target = name.format(s=store)
    saves = [lambda p: save_chronovolume(cv, p, overwrite=True)]
    if not target.endswith(".vti"):  # (`save` writes zarr whatever the name)
        saves.append(lambda p: cv.save(p, overwrite=True))
    for save in saves:
        with pytest.raises(OutputIsInputError):
            save(target)
    assert digest(store) == before
    cv.save(tmp_path / "cv.zarr")  # apart from it: saved
