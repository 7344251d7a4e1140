"""Write a store or file atomically: build it at a hidden sibling, rename it when complete.

The sibling is ``.NAME.partial-<pid>-<hex>`` (a file keeps NAME's suffix), named after the
process that writes it. Whatever happens to a write, nothing half-written ever appears at
NAME, and no partial of it stays behind:

- A write that fails (an exception, Ctrl-C, a failed rename) removes its own partial; every
  rename and move sits inside that cleanup.
- A write killed outright (kill -9, power loss) cannot clean up. The next write of the same
  NAME that commits, by whichever path, removes the partials that such dead writers left:
  those whose pid is no longer a live process, the older names without a pid, and the
  streamed run's ``.NAME.partial-run`` folder (`chronocl.integration.runs.streaming`) unless a
  live run holds its lock. A partial of a live concurrent writer is never touched. (Liveness is
  that of the
  pid on this machine: writers of one output on several hosts are not told apart.)
- Replacing an existing NAME (overwrite) exchanges the two in one step where the system can
  (Linux renameat2), so NAME is always either the complete old output or the complete new
  one; elsewhere the old one is moved aside for the instant of the rename.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import logging
import os
import re
import shutil
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

from chronocl.core.errors import OutputExistsError
from chronocl.core.paths import check_output

log = logging.getLogger("chronocl")

RUN_DIR = ".chronocl-run"  # bookkeeping of a streamed run, inside its .NAME.partial-run
RUN_LOCK = "lock"  # RUN_DIR/RUN_LOCK: flock-ed by the live process that owns the run


# -- names of the hidden siblings -------------------------------------------------------------
def partial_path(target: Path, suffix: str = "", kind: str = "partial") -> Path:
    """A fresh hidden sibling of `target` owned by this process: ``.NAME.<kind>-<pid>-<hex>``."""
    return target.parent / f".{target.name}.{kind}-{os.getpid()}-{uuid.uuid4().hex[:12]}{suffix}"


def _sibling_pattern(name: str) -> re.Pattern[str]:
    """Hidden siblings that writes of `name` make: group pid (pid names), run (streamed run)."""
    suffix = Path(name).suffix
    return re.compile(
        rf"\.{re.escape(name)}\.(?:partial|old)-"
        r"(?:(?P<pid>\d+)-[0-9a-f]{8,32}|[0-9a-f]{8}|(?P<run>run))"  # pid-hex, old uuid, run
        + (rf"(?:{re.escape(suffix)})?" if suffix else "")  # a file keeps its suffix
    )


def pid_alive(pid: int) -> bool:
    """Whether `pid` is a live process here (a zombie, killed but not yet reaped, is not)."""
    if pid == os.getpid():
        return True
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # it exists (EPERM: another user's)
        pass
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True
    state = stat.rpartition(")")[2].split()[:1]
    return state not in (["Z"], ["X"])


def lock_run(folder: Path) -> int | None:
    """Take the lock of the streamed run at `folder`: its file descriptor, held until closed.

    None when `folder` has no lock file (it is not a run, or one from before locks); raises
    BlockingIOError when a live process holds it.
    """
    lock = folder / RUN_DIR / RUN_LOCK
    try:
        fd = os.open(lock, os.O_RDWR)
    except (FileNotFoundError, NotADirectoryError):
        return None
    try:
        _flock(fd)
        if os.fstat(fd).st_ino != os.stat(lock).st_ino:  # removed and made anew meanwhile
            raise FileNotFoundError(lock)
    except FileNotFoundError:
        os.close(fd)
        return None
    except BaseException:
        os.close(fd)
        raise
    return fd


def _flock(fd: int) -> None:
    try:
        import fcntl
    except ImportError:  # pragma: no cover - no flock: the pid written in the file decides
        pid = int(os.read(fd, 32) or b"0")
        if pid_alive(pid) and pid != os.getpid():
            raise BlockingIOError(errno.EWOULDBLOCK, "locked by a live process") from None
        return
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)


def discard_run(path: Path, target: Path, fd: int | None) -> bool:
    """Remove the streamed run folder `path` of `target`, locked by `fd` (None: made before
    locks). It is first moved aside under its lock, so no run resumes it meanwhile; the lock
    is released either way. False when it could not be moved (gone, or not ours to move).
    """
    gone = partial_path(target)
    try:
        os.replace(path, gone)
    except OSError:
        return False
    finally:
        if fd is not None:
            os.close(fd)
    remove_path(gone)
    return True


def remove_path(path: Path) -> None:
    """Remove a file or folder tree; what is already gone is no error."""
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)
    except OSError as exc:  # pragma: no cover - reported, never fatal to a finished write
        log.warning("could not remove %s: %s", path, exc)


def remove_stale(target: Path) -> list[Path]:
    """Remove the hidden partials of `target` that no live writer owns; returns them.

    Called once `target` is committed. Kept: partials named after a live pid (this
    process's included) and a streamed run whose lock a live process holds.
    """
    pattern = _sibling_pattern(target.name)
    try:
        names = os.listdir(target.parent)
    except OSError:
        return []
    removed = []
    for name in names:
        m = pattern.fullmatch(name)
        if m is None:
            continue
        path = target.parent / name
        if m["pid"] is not None:
            if pid_alive(int(m["pid"])):
                continue
            remove_path(path)
        elif m["run"] is not None:
            try:
                fd = lock_run(path)
            except OSError:  # held: a live run (or a lock we cannot take: leave it)
                continue
            if not discard_run(path, target, fd):
                continue
        else:
            remove_path(path)  # a name without a pid: from a writer before pids
        removed.append(path)
    if removed:
        log.info(
            "removed %d partial output(s) of %s left by interrupted runs", len(removed), target
        )
    return removed


# -- committing -------------------------------------------------------------------------------
def _load_renameat2():
    if not sys.platform.startswith("linux"):
        return None
    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # pragma: no cover - a libc without it
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_renameat2 = _load_renameat2()
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


def exchange(a: Path, b: Path) -> bool:
    """Swap `a` and `b` in one step; False where the system or file system cannot."""
    if _renameat2 is None:
        return False
    if _renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(code, os.strerror(code), os.fspath(b))


def replace(tmp: Path, target: Path) -> None:
    """Put the finished `tmp` (file or folder) at `target`, replacing whatever is there.

    On success `tmp` no longer exists. On failure `target` is as it was and `tmp` is still
    there for the caller to remove. Then removes the partials of `target` dead writers left.
    """
    if not (tmp.is_dir() or target.is_dir()):
        os.replace(tmp, target)  # a file over a file, or over nothing: one rename
    elif not os.path.lexists(target) and rename_new(tmp, target):
        pass
    elif exchange(tmp, target):
        remove_path(tmp)  # the old output
    else:
        # Folders cannot be replaced in one rename here: move the old one aside for the instant.
        old = partial_path(target, kind="old")
        os.replace(target, old)
        try:
            os.replace(tmp, target)
        except BaseException:
            os.replace(old, target)
            raise
        remove_path(old)
    try:
        remove_stale(target)
    except Exception as exc:  # pragma: no cover - the output is written; say so, go on
        log.warning("could not remove old partial outputs of %s: %s", target, exc)


def rename_new(tmp: Path, target: Path) -> bool:
    """Rename `tmp` to the free name `target`; False if something took the name meanwhile."""
    try:
        os.rename(tmp, target)
    except OSError as exc:
        if exc.errno in (errno.EEXIST, errno.ENOTEMPTY, errno.ENOTDIR, errno.EISDIR):
            return False
        raise
    return True


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling directory that replaces `path` when the block succeeds."""
    target = check_output(path, overwrite)
    target.parent.mkdir(parents=True, exist_ok=True)
    with _replacing(partial_path(target), target) as tmp:
        yield tmp


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary sibling file path that replaces `path` when the block succeeds."""
    target = check_output(path, overwrite)
    if target.is_dir():
        raise OutputExistsError(
            f"output {str(target)!r} is a folder and this output is one file; "
            "remove the folder or choose another name"
        )
    target.parent.mkdir(parents=True, exist_ok=True)
    with _replacing(partial_path(target, target.suffix), target) as tmp:
        yield tmp


@contextlib.contextmanager
def _replacing(tmp: Path, target: Path) -> Iterator[Path]:
    """Yield `tmp`, which replaces `target` when the block succeeds and is removed otherwise."""
    try:
        yield tmp
        replace(tmp, target)
    except BaseException:
        remove_path(tmp)
        raise
