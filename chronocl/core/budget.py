"""Memory budgets: '2GB', '512MiB' or a byte count, parsed once at the edge."""

from __future__ import annotations

import os

from dask.utils import format_bytes, parse_bytes

from chronocl.core.errors import InvalidParameterError
from chronocl.core.tuning import TUNING

DEFAULT_MEMORY = "2GB"
MAX_MEMORY = 2**50  # 1 PiB: a larger budget is a typo, not a machine


def parse_memory(value: str | int | float | None, default: str = DEFAULT_MEMORY) -> int:
    """A byte budget from '2GB', '512MiB', '1e9' or an int; it must be positive."""
    if value is None:
        value = default
    try:
        if isinstance(value, bool):
            raise TypeError(value)
        n = int(value) if isinstance(value, int | float) else int(parse_bytes(str(value)))
    except OverflowError:  # 1e999 or inf: infinitely many bytes
        n = MAX_MEMORY + 1
    except (ValueError, TypeError):
        raise InvalidParameterError(
            f"memory budget {value!r} is not a size; write it like 512MB, 2GB or 1.5GiB"
        ) from None
    if n <= 0:
        raise InvalidParameterError(f"memory budget {value!r} must be positive, e.g. 2GB")
    if n > MAX_MEMORY:
        raise InvalidParameterError(
            f"memory budget {value!r} is more than {human(MAX_MEMORY)}, far beyond any "
            "machine's memory; give the memory you want chronocl to use, e.g. 2GB"
        )
    return n


def interactive_memory() -> int:
    """The default budget of an interactive session (`Session`'s resident steps) and the
    default memory limit of a viewer process (everything it holds, every client's steps and
    frames: `chronocl.core.process_memory`): half the memory free now (within a container's
    limit), at least DEFAULT_MEMORY. A window of the sizes users bring (10 float32 steps of
    512^3 are 5.4 GB) stays resident beside two views' frames (2.3 GB each) where 21 GB are
    free; past that the limit streams the window rather than going over. It was a third while the
    frames' memory was not counted against the limit (a soak then peaked at 1.3x it); now
    that it is, a third would stream the users' case. `--memory` / `memory=` set it."""
    return max(parse_memory(DEFAULT_MEMORY), available_bytes() // 2)


def available_bytes() -> int:
    """The memory free now, within a container's limit."""
    import psutil

    free = int(psutil.virtual_memory().available)
    limit = _cgroup_room()
    return free if limit is None else min(free, limit)


def _cgroup_room() -> int | None:
    """Bytes a cgroup v2 memory limit leaves this process's group (None: no limit)."""
    try:
        with open("/sys/fs/cgroup/memory.max") as f:
            text = f.read().strip()
        with open("/sys/fs/cgroup/memory.current") as f:
            used = int(f.read().strip())
    except (OSError, ValueError):
        return None
    return None if text == "max" else max(0, int(text) - used)


def human(n: float) -> str:
    """Bytes for people: '1.50 GiB'."""
    return format_bytes(int(n))


def _load_libc():
    """The C library, or None where it cannot be loaded."""
    import ctypes
    import ctypes.util

    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None


_libc = _load_libc()
malloc_trim = getattr(_libc, "malloc_trim", None)  # glibc's; None: not glibc, nothing to trim

# glibc raises its mmap threshold to the size of each large block freed (up to 32 MiB), after
# which decoded chunks and slabs come from per-thread arenas that keep them when freed: with
# 16 threads a 64 MB budget peaked at 1.25-1.4x (tests/test_budget_threads.py).
# A fixed threshold (`TUNING.mmap_threshold`, `trim_threshold`) keeps every block of a MiB or
# more in its own mapping, handed back on free.
_M_MMAP_THRESHOLD = -3
_M_TRIM_THRESHOLD = -1
_bounded: list[bool] = []


def bound_allocator() -> bool:
    """Fix glibc's mmap threshold at TUNING.mmap_threshold for this process (once), so that what the
    threads of a run free goes back to the system however many threads there are; False on
    other C libraries."""
    if not _bounded:
        mallopt = getattr(_libc, "mallopt", None)
        # The trim threshold too: the raised mmap threshold had raised it to twice as much.
        ok = mallopt is not None and mallopt(_M_MMAP_THRESHOLD, TUNING.mmap_threshold)
        ok = ok and mallopt(_M_TRIM_THRESHOLD, TUNING.trim_threshold)
        _bounded.append(bool(ok))
        if ok and malloc_trim is not None:
            malloc_trim(0)  # what the arenas kept under the old thresholds
    return _bounded[0]


def resident_bytes() -> int | None:
    """This process's resident memory (Linux), or None where it cannot be read cheaply."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def peak_resident_bytes() -> int | None:
    """This process's peak resident memory (the kernel's VmHWM, Linux), or None where /proc
    does not say."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


class GrowthGuard:
    """Keeps the process's growth since creation near `allowance` bytes.

    zarr decodes and encodes chunks on several threads, and glibc keeps what each thread's
    arena freed for that thread's next allocation: tens of MB beyond what is in use, which a
    memory budget cannot plan for. `check()` hands the freed memory back to the system
    (malloc_trim) when the process has grown by more than the allowance. It does nothing
    while the process stays within it, since memory handed back costs a page fault per page
    when it is used again, nor until the process grows again by a quarter of the allowance
    beyond what a trim could not hand back.
    """

    def __init__(self, allowance: int) -> None:
        self.allowance = allowance
        self.base = resident_bytes()
        self.floor = 0  # resident bytes after the last trim
        self.trims = 0

    def check(self) -> None:
        if malloc_trim is None or self.base is None:
            return
        now = resident_bytes()
        if now is None or now - self.base <= self.allowance:
            return
        if now > self.floor + self.allowance // 4:
            malloc_trim(0)
            self.trims += 1
            self.floor = resident_bytes() or 0
