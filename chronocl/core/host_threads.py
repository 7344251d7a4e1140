"""The threads that share host-side copies and conversions among the cores.

One pool for the process, made when first needed, with a thread per core (at most 8; the
environment variable CHRONOCL_THREADS sets the count exactly, e.g. 1 to pin chronocl's host
work to one core or 16 to test what grows with threads on a small machine): the
stacking of bricks that cannot be read in place, the conversion of bricks to a device format
and of chronovolumes to display textures all split their work over it. numpy releases the
GIL while it copies and converts plain arrays, so the pieces run side by side.
"""

from __future__ import annotations

import itertools
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from chronocl.core import env
from chronocl.core.errors import InvalidParameterError
from chronocl.core.tuning import TUNING

MAX_THREADS = 8

_lock = threading.Lock()
_held: list[ThreadPoolExecutor] = []


THREADS_ENV = "CHRONOCL_THREADS"
THREAD_PREFIX = "chronocl-host"  # the pool's thread names
MAX_FORCED = 256  # more is a typo


def workers() -> int:
    """Threads in the pool: CHRONOCL_THREADS if set, else one per core, at most MAX_THREADS."""
    forced = env.get(THREADS_ENV)
    if forced:
        if not forced.isdigit() or not 1 <= int(forced) <= MAX_FORCED:
            raise InvalidParameterError(
                f"{THREADS_ENV}={forced!r} is not a thread count; set it to a whole number "
                f"from 1 to {MAX_FORCED}, or unset it to use one thread per core"
            )
        return int(forced)
    return max(1, min(MAX_THREADS, os.cpu_count() or 1))


def pool() -> ThreadPoolExecutor:
    """The process's host-thread pool."""
    with _lock:
        if not _held:
            _held.append(ThreadPoolExecutor(workers(), thread_name_prefix=THREAD_PREFIX))
        return _held[0]


def copy_all(pairs: Sequence[tuple[np.ndarray, np.ndarray]]) -> None:
    """dst[...] = src for each (dst, src), each pair cut along its first axis into pieces
    spread over the pool's threads (on the calling thread when small)."""
    total = sum(dst.nbytes for dst, _ in pairs)
    n = workers()
    if n == 1 or total < TUNING.parallel_min_bytes:
        for dst, src in pairs:
            dst[...] = src
        return
    pieces = []
    for dst, src in pairs:
        rows = dst.shape[0] if dst.ndim else 1
        cuts = max(1, min(rows, round(n * dst.nbytes / total) or 1))
        edges = np.linspace(0, rows, cuts + 1).round().astype(int)
        pieces += [(dst[a:b], src[a:b]) for a, b in itertools.pairwise(edges) if b > a]
    list(pool().map(lambda p: np.copyto(p[0], p[1]), pieces))
