"""Memory handed to an OpenCL device: the one place device buffers are made.

Every path that gives arrays to a device (integration, the sliding kernels, gathers,
recolouring, resident steps, transfers, the roofline) makes its buffers here, and keeps two
promises through this module:

- **No buffer is larger than the device's largest allocation** (`max_alloc`). Asking for more
  raises `DeviceLimitError` before anything is enqueued; callers split their work (`spans`
  for voxel-wise kernels, `chronocl.engine.in_place` and `chronocl.engine.transfer` for
  bricks). ``CHRONOCL_MAX_ALLOC`` (e.g. "1MB") lowers the limit, so the suite drives the split
  paths on small data.
- **Work enqueued on host memory finishes before that memory can be freed.** `DeviceWork`
  holds the device's lock and every buffer made through it, and waits for its queues on every
  way out, an exception's included: a gather whose second enqueue failed once unwound, freed
  the host array its first kernel was writing, and the process died in that kernel.
"""

from __future__ import annotations

import logging

import numpy as np

from chronocl.core import env
from chronocl.core.errors import ChronoclError

log = logging.getLogger("chronocl.engine")

MAX_ALLOC_VAR = "CHRONOCL_MAX_ALLOC"


class DeviceLimitError(ChronoclError, MemoryError):
    """A buffer over the device's largest allocation: the caller must split its work."""


def max_alloc(dc) -> int:
    """The largest buffer `dc` (a `DeviceContext`) may hold: the device's own limit, lowered
    by ``CHRONOCL_MAX_ALLOC`` where it is set (read on every call, so a test may set it)."""
    device = int(dc.info.max_alloc)
    given = env.get(MAX_ALLOC_VAR)
    if not given:
        return device
    from chronocl.core.budget import parse_memory

    return max(1, min(device, parse_memory(given)))


def spans(n: int, item_bytes: int, limit: int, multiple: int = 64) -> list[tuple[int, int]]:
    """Ranges [a, b) of `n` items, each at most `limit` bytes at `item_bytes` an item (the
    largest array's), cut on multiples of `multiple` items (64: every cut of a 64-byte aligned
    array of 1-byte items or more stays aligned). One range where everything fits."""
    if n * item_bytes <= limit:
        return [(0, n)]
    per = limit // max(1, item_bytes) // multiple * multiple
    if per < 1:
        raise DeviceLimitError(
            f"the device's largest buffer ({limit} bytes) holds fewer than {multiple} items of "
            f"{item_bytes} bytes; raise {MAX_ALLOC_VAR} or use a device with more memory"
        )
    return [(a, min(n, a + per)) for a in range(0, n, per)]


def check(dc, nbytes: int, what: str) -> None:
    """Raise `DeviceLimitError` where `nbytes` is over the largest buffer of `dc`."""
    limit = max_alloc(dc)
    if nbytes > limit:
        raise DeviceLimitError(
            f"{what} of {nbytes} bytes is over the device's largest buffer ({limit} bytes; "
            f"{dc.info.label}): split the work (a chronocl bug if you see this)"
        )


def buffer(
    dc,
    host: np.ndarray | None = None,
    *,
    nbytes: int | None = None,
    access: str = "r",
    in_place: bool = False,
    pinned: bool = False,
):
    """A buffer on `dc`'s device: over `host` (read where it lies with `in_place`, a CPU
    device's host pointer; else a copy of it, for device reads), or `nbytes` uninitialised
    (`pinned`: in host memory the device maps). `access` is what kernels do: "r", "w" or "rw".
    The caller keeps it alive until the work on it has finished (`DeviceWork` does)."""
    import pyopencl as cl

    mf = cl.mem_flags
    flags = {"r": mf.READ_ONLY, "w": mf.WRITE_ONLY, "rw": mf.READ_WRITE}[access]
    size = max(1, int(host.nbytes if host is not None else nbytes))
    check(dc, size, "a device buffer")
    if host is None:
        return cl.Buffer(dc.context, flags | (mf.ALLOC_HOST_PTR if pinned else 0), size)
    if in_place and not host.flags.c_contiguous:
        if access != "r":
            raise ValueError("a device writes in place only into a C-contiguous array")
        in_place = False  # a copy for the device (its host pointer would be a temporary's)
    if in_place:
        return cl.Buffer(dc.context, flags | mf.USE_HOST_PTR, hostbuf=host)
    if access == "w":
        return cl.Buffer(dc.context, flags, size)
    return cl.Buffer(dc.context, flags | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(host))


class DeviceWork:
    """`with DeviceWork(dc) as work:` the device's lock held, buffers made through `work`
    kept alive, and on the way out (however it goes) every queue in `queues` waited for (the
    device's queue; a caller that enqueues on others adds them), so no host memory the
    enqueued work reads or writes is freed under it."""

    def __init__(self, dc) -> None:
        self.dc = dc
        self.queues = [dc.queue]
        self.held: list = []

    def __enter__(self) -> DeviceWork:
        self.dc.lock.acquire()
        return self

    def __exit__(self, kind, exc, tb) -> None:
        try:
            self.finish(failing=exc is not None)
        finally:
            self.held = []
            self.dc.lock.release()

    def finish(self, failing: bool = False) -> None:
        """Wait for every queue. While an error unwinds, a failed wait is logged, not raised
        (the error that brought us here is the one to report), and every queue is waited for."""
        for q in self.queues:
            try:
                q.finish()
            except Exception as exc:
                if not failing:
                    raise
                log.error("chronocl: waiting for the device after an error failed too: %r", exc)

    def hold(self, obj):
        """Keep `obj` (a buffer, a host array, a mapping) alive until the work has finished."""
        self.held.append(obj)
        return obj

    def buffer(self, host: np.ndarray | None = None, **options):
        """`buffer(self.dc, host, **options)`, held; the host array is held with it."""
        if host is not None:
            self.held.append(host)
        return self.hold(buffer(self.dc, host, **options))

    def read(self, out: np.ndarray, buf, in_place: bool, queue=None) -> None:
        """Enqueue what makes `out` hold `buf`'s contents once the queue has finished: a map
        and unmap where `buf` wraps `out` (`in_place`), else a copy."""
        import pyopencl as cl

        queue = queue or self.queues[0]
        if in_place:
            mapped, _ = cl.enqueue_map_buffer(
                queue, buf, cl.map_flags.READ, 0, out.shape, out.dtype, is_blocking=False
            )
            mapped.base.release(queue)
        else:
            cl.enqueue_copy(queue, out, buf, is_blocking=False)
        self.held.append(out)
