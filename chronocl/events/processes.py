"""Labelling a stored series' steps on worker processes, one step per core at once.

connected-components-3d holds the GIL while it labels (4.1 releases it nowhere), so threads
label one step at a time. For a series read from a store, `find` (`chronocl.events.run`)
therefore starts `Labellers`: a few Python processes, each given the series once (pickled: the
store's path and zarr array, a few kilobytes, never its data) and the job's mask, that read
each step they are given from the store themselves into a buffer they keep, then mask, label
and measure it (`chronocl.events.features.label_step`) and count its overlaps with the step
before it: only the step's number goes out and its features and overlaps come back, the labels
never leave the worker.

For the overlaps each worker publishes its step's shown voxels (flat indices, int64) and their
labels (uint32), twelve bytes a shown voxel, as two files in a folder in shared memory
(/dev/shm where there is one); the worker of the next step waits for them, then looks those
voxels up in its own labels (`chronocl.events.tracking.overlaps`). A step waits only for one
given out before it, so the workers never wait on each other in a circle. The caller removes a
step's files once the next step is matched (`release`), and the folder when it closes; closing
early (an error, an interrupted find) tells a worker waiting for a step that will not come to
give up. A caller that dies (killed, out of memory) cannot: its workers then remove the folder
(their stdin ends, or they find themselves adopted while waiting), and the next `Labellers`
removes any folder whose caller, named by the pid in its name, is gone (only folders of
its own host and PID namespace: a pid says nothing elsewhere).

The workers ignore SIGINT: they share the caller's process group, and a Ctrl-C is the
caller's to act on (it ends them by closing). Every answer is pickled to bytes first, so an
error that does not pickle in the worker, or unpickle in the caller, becomes a
LabellingWorkerError naming it, and the step's Future is always completed.

The workers are plain ``python -c`` children speaking pickle over their stdin and stdout, not
multiprocessing's: its spawn and forkserver start methods run the caller's main script again
in every child (a script without an ``if __name__ == "__main__"`` guard would start ``events``
once more there), and fork copies a process whose threads (zarr's event loop, the host pool)
the child cannot use.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import pickle
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from queue import SimpleQueue
from typing import Any, BinaryIO

import numpy as np

from chronocl.core.budget import peak_resident_bytes
from chronocl.core.errors import ChronoclError
from chronocl.events.features import Feature, Mask, Periodic
from chronocl.events.tracking import Edge, edges_of

SHARED_MEMORY = Path("/dev/shm")  # a tmpfs: the voxel files never reach a disk
STOP = "stop"  # the file `close` leaves in the folder: workers waiting for a step give up
POLL_S = 0.002  # how often a worker waiting for the step before its own looks for it
EXIT_WAIT_S = 10.0  # how long `close` waits for a worker to exit before killing it
# The child's bootstrap: the caller's import path first, so it imports the same chronocl.
# SIGINT ignored first: the workers share the caller's process group, so a Ctrl-C meant for
# the caller would print a KeyboardInterrupt traceback from each; the caller ends them (`close`).
BOOTSTRAP = (
    "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN); "
    "import pickle, sys; sys.path[:] = pickle.load(sys.stdin.buffer); "
    "from chronocl.events.processes import serve; serve()"
)
# A folder's name: PREFIX, where its caller runs (`_here`), its pid, "-", a random part.
PREFIX = "chronocl-events-"


class LabellingWorkerError(ChronoclError, RuntimeError):
    """A worker process labelling steps exited before it answered, or its answer (an error
    that does not pickle or unpickle) could not be passed back."""


@dataclass(frozen=True)
class Labelled:
    """A step labelled by a worker: its features, the voxels each pair (feature of the step
    before, feature of this one) shares (None for the window's first step), what it took
    (seconds reading; seconds masking, labelling, measuring and overlapping; seconds waiting
    for the step before) and the worker's peak RSS so far (bytes)."""

    step: int
    features: tuple[Feature, ...]
    shared: dict[tuple[int, int], int] | None
    read_s: float
    label_s: float
    wait_s: float
    pid: int
    peak_rss: int


class Labellers:
    """`count` worker processes labelling the steps of `series` under `mask` (the module's
    docstring). `submit(step, previous)` gives a Future of the step's `Labelled` (`previous`,
    the window's step before it, or None); `edges` are its overlap edges with that step;
    `release` removes a step's files. A context manager: leaving it lets the steps being
    labelled finish, drops those not yet started and ends the workers."""

    def __init__(
        self,
        series: object,
        mask: Mask,
        connectivity: int,
        periodic: Periodic,
        spacing_xyz: tuple[float, ...],
        origin_xyz: tuple[float, ...],
        count: int,
    ) -> None:
        # first, so that a series that does not pickle (TypeError...) leaves nothing behind
        setup = pickle.dumps((series, mask, connectivity, periodic, spacing_xyz, origin_xyz))
        shared = SHARED_MEMORY if SHARED_MEMORY.is_dir() else Path(tempfile.gettempdir())
        remove_stale(shared)
        self.folder = tempfile.mkdtemp(prefix=f"{PREFIX}{_here()}-{os.getpid()}-", dir=shared)
        self._tasks: SimpleQueue[tuple[int, int | None, Future] | None] = SimpleQueue()
        self._procs: list[subprocess.Popen] = []
        self._threads: list[threading.Thread] = []
        self.peaks: dict[int, int] = {}  # worker pid -> its peak RSS (bytes)
        try:
            for _ in range(count):
                proc = subprocess.Popen(
                    [sys.executable, "-c", BOOTSTRAP], stdin=subprocess.PIPE, stdout=subprocess.PIPE
                )
                self._procs.append(proc)
                assert proc.stdin is not None
                pickle.dump(list(sys.path), proc.stdin)
                pickle.dump(self.folder, proc.stdin)  # first: a worker cut off removes it
                proc.stdin.write(setup)
                proc.stdin.flush()
                thread = threading.Thread(
                    target=self._feed, args=(proc,), name="chronocl-events-feed", daemon=True
                )
                thread.start()
                self._threads.append(thread)
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> Labellers:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def submit(self, step: int, previous: int | None) -> Future:
        future: Future = Future()
        self._tasks.put((int(step), None if previous is None else int(previous), future))
        return future

    def _feed(self, proc: subprocess.Popen) -> None:
        """One worker's steps: each taken from the shared queue in turn, sent, answered. Every
        step taken is completed, whatever the answer: `find` waits on it."""
        assert proc.stdin is not None and proc.stdout is not None
        while (task := self._tasks.get()) is not None:
            step, previous, future = task
            if not future.set_running_or_notify_cancel():
                continue  # given up before it started
            try:
                try:
                    pickle.dump((step, previous), proc.stdin)
                    proc.stdin.flush()
                    kind, said, answer_bytes = pickle.load(proc.stdout)  # `_answer`'s
                except (OSError, EOFError, pickle.UnpicklingError):
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        proc.wait(timeout=EXIT_WAIT_S)  # its exit code, once it has one
                    future.set_exception(
                        LabellingWorkerError(
                            f"the worker process labelling step {step} exited (code "
                            f"{proc.poll()}) before it answered, e.g. out of memory: give find "
                            "a smaller memory= budget, or set CHRONOCL_THREADS=1 to label on "
                            "threads"
                        )
                    )
                    return
                try:
                    answer = pickle.loads(answer_bytes)
                except BaseException as exc:  # e.g. an error class whose __init__ takes more
                    future.set_exception(
                        LabellingWorkerError(
                            f"step {step}'s answer ({said or kind}) did not unpickle here "
                            f"({type(exc).__name__}: {exc}): set CHRONOCL_THREADS=1 to label "
                            "on threads and see it raised as itself"
                        )
                    )
                    continue  # the stream is whole (the answer came as bytes): go on
                if kind == "error":
                    future.set_exception(answer)
                else:
                    self.peaks[answer.pid] = max(self.peaks.get(answer.pid, 0), answer.peak_rss)
                    future.set_result(answer)
            finally:
                if not future.done():  # whatever went wrong, find must not wait for ever
                    future.set_exception(
                        LabellingWorkerError(
                            f"step {step}'s answer was lost: set CHRONOCL_THREADS=1 to label "
                            "on threads"
                        )
                    )

    @staticmethod
    def features(done: Labelled) -> tuple[Feature, ...]:
        return done.features

    @staticmethod
    def edges(before: Labelled, done: Labelled) -> list[Edge]:
        """The overlap edges from the features of the step before (`before`) to `done`'s."""
        assert done.shared is not None
        return edges_of(before.step, before.features, done.step, done.features, done.shared)

    def release(self, done: Labelled) -> None:
        """Remove a step's voxel files: the step after it has counted its overlaps."""
        for path in _files(self.folder, done.step):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(path)

    def close(self) -> None:
        """Let the steps being labelled finish, end the workers, remove the folder."""
        with contextlib.suppress(OSError):
            Path(self.folder, STOP).touch()  # a step waited for may never come now
        for _ in self._threads:
            self._tasks.put(None)
        for thread in self._threads:
            thread.join()
        while not self._tasks.empty():  # steps no worker took: never started
            task = self._tasks.get()
            if task is not None:
                task[2].cancel()
        for proc in self._procs:
            with contextlib.suppress(OSError):
                proc.stdin.close()  # type: ignore[union-attr]
        for proc in self._procs:
            try:
                proc.wait(EXIT_WAIT_S)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            with contextlib.suppress(OSError):
                proc.stdout.close()  # type: ignore[union-attr]
        shutil.rmtree(self.folder, ignore_errors=True)


def remove_stale(shared: Path) -> None:
    """Remove the folders in `shared` of callers that died (killed, out of memory) before
    their workers could remove them: a folder's name holds where its caller ran and its pid.
    Only folders of this host and PID namespace are judged: a pid elsewhere (a container
    sharing /dev/shm, a temporary folder on a network file system) says nothing here."""
    mine = f"{PREFIX}{_here()}-"
    for folder in shared.glob(f"{mine}*-*"):
        owner = folder.name[len(mine) :].split("-", 1)[0]
        if owner.isdigit() and not _alive(int(owner)):
            shutil.rmtree(folder, ignore_errors=True)


def _here() -> str:
    """This host and PID namespace, as a short name (a pid means a process only within them)."""
    try:
        namespace = os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        namespace = 0
    seen = f"{socket.gethostname()}:{namespace}".encode()
    return hashlib.blake2s(seen, digest_size=4).hexdigest()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    return True


def _files(folder: str, step: int) -> tuple[str, str]:
    """A step's published voxels (flat indices, int64) and their labels (uint32)."""
    return os.path.join(folder, f"{step}.voxels"), os.path.join(folder, f"{step}.owners")


# -- in the worker -----------------------------------------------------------------------------
def serve() -> None:
    """A worker's loop: the folder and the setup, then steps until its stdin closes; one answer
    per step, ("ok", Labelled) or ("error", the exception), pickled to bytes first so that an
    error that does not pickle becomes a LabellingWorkerError naming it. Its stdin closing (the
    caller closed it, or died: killed, out of memory) or the caller gone removes the folder:
    the caller may never do it."""
    stdin = sys.stdin.buffer
    answers: BinaryIO = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # a stray print cannot break the pipe
    folder = pickle.load(stdin)
    caller = os.getppid()
    try:
        # a setup that fails (a store out of reach...) exits with its traceback on stderr
        worker = _Worker(*pickle.load(stdin), folder=folder, caller=caller)
        while True:
            try:
                step, previous = pickle.load(stdin)
            except EOFError:  # no more steps will come: closed, or the caller died
                shutil.rmtree(folder, ignore_errors=True)
                return
            try:
                pickle.dump(_answer(worker, step, previous), answers)
                answers.flush()
            except BrokenPipeError:  # nobody reads the answers: the caller died
                shutil.rmtree(folder, ignore_errors=True)
                return
    finally:
        if os.getppid() != caller:  # adopted: the caller died
            shutil.rmtree(folder, ignore_errors=True)


def _answer(worker: _Worker, step: int, previous: int | None) -> tuple[str, str, bytes]:
    """The step's answer: ("ok", "", the Labelled pickled) or ("error", the error's type and
    message, the error pickled; where it does not pickle, a LabellingWorkerError naming it and
    carrying its traceback)."""
    try:
        return ("ok", "", pickle.dumps(worker.label(step, previous)))
    except Exception as exc:  # sent back; the caller raises it
        said = f"{type(exc).__name__}: {exc}"
        try:
            return ("error", said, pickle.dumps(exc))
        except Exception as why:
            text = "".join(traceback.format_exception(exc)).strip().replace("\n", " | ")
            error = LabellingWorkerError(
                f"step {step} failed with {said}, an error that does not pickle "
                f"({type(why).__name__}: {why}); the worker's traceback: {text}"
            )
            return ("error", said, pickle.dumps(error))


class _Worker:
    def __init__(
        self,
        series: Any,
        mask: Mask,
        connectivity: int,
        periodic: Periodic,
        spacing_xyz: Sequence[float],
        origin_xyz: Sequence[float],
        folder: str,
        caller: int,
    ) -> None:
        from chronocl.core.memory import aligned_empty

        self.series, self.mask, self.folder, self.caller = series, mask, folder, caller
        self.connectivity, self.periodic = connectivity, periodic
        self.spacing_xyz, self.origin_xyz = spacing_xyz, origin_xyz
        shape = series.volume_shape
        # used again for every step: a fresh step-sized array costs a page fault per page
        self.out = aligned_empty((shape[0], 1, *shape[1:]), series.dtype)
        self.shown = np.empty(shape, bool)

    def label(self, step: int, previous: int | None) -> Labelled:
        from chronocl.events.features import label_step
        from chronocl.events.tracking import overlaps

        clock = time.perf_counter
        t0 = clock()
        values = self.series.read_brick([step], out=self.out, per_call=1)[:, 0]
        t1 = clock()
        found = label_step(
            values,
            self.mask,
            step,
            self.connectivity,
            self.periodic,
            self.spacing_xyz,
            self.origin_xyz,
            scratch=self.shown,
        )
        assert found.voxels is not None
        self._publish(step, found.voxels, found.labels.reshape(-1)[found.voxels])
        shared, waited = None, 0.0
        if previous is not None:
            t2 = clock()
            voxels, owners = self._wait_for(previous)
            waited = clock() - t2
            shared = overlaps(None, found.labels, voxels, owners)
        return Labelled(
            step,
            found.features,
            shared,
            t1 - t0,
            clock() - t1 - waited,
            waited,
            os.getpid(),
            peak_resident_bytes() or 0,
        )

    def _publish(self, step: int, voxels: np.ndarray, owners: np.ndarray) -> None:
        """The step's shown voxels and their labels, for the next step's worker; each file
        written aside and renamed into place, the labels last (a waiter looks for them)."""
        for path, array in zip(_files(self.folder, step), (voxels, owners), strict=True):
            aside = path + ".part"
            array.tofile(aside)
            os.replace(aside, path)

    def _wait_for(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """Another worker's step, once published; LabellingWorkerError once the caller closes."""
        voxels, owners = _files(self.folder, step)
        stop = os.path.join(self.folder, STOP)
        while not os.path.exists(owners):
            if (
                os.path.exists(stop)
                or not os.path.isdir(self.folder)  # removed: nothing will be published there
                or os.getppid() != self.caller  # the caller died
            ):
                raise LabellingWorkerError(f"step {step} was given up before it was labelled")
            time.sleep(POLL_S)
        return np.fromfile(voxels, np.int64), np.fromfile(owners, np.uint32)
