"""Arrays that stay on an OpenCL device (pyopencl arrays) beside host numpy arrays.

A sliding window on an engine that copies bricks (a GPU) keeps its state on the device between
slides (`chronocl.integration.interactive.slider`): the elementwise kernels
(`chronocl.engine.elementwise`) take either kind of array, and a device array passes as its
buffer, with no copy either way. These helpers make, fill and fetch them on a device context's
queue, holding its lock.
"""

from __future__ import annotations

import numpy as np

from chronocl.core.memory import recycled_empty
from chronocl.engine.buffers import check


def on_device(a: object) -> bool:
    """Whether `a` is a device array (pyopencl.array.Array)."""
    try:
        import pyopencl.array as cla
    except ImportError:  # pragma: no cover - no OpenCL at all: nothing is on a device
        return False
    return isinstance(a, cla.Array)


def empty(dc, shape: tuple[int, ...], dtype: object, device: bool):
    """An uninitialised array on the device of `dc` (`device`) or on the host (aligned, on the
    memory of a dead one of its size where there is one: a slide's combines make and drop a
    partial each, whose fresh pages were a third of a combine at 128^3-256^3 here)."""
    if not device:
        return recycled_empty(shape, dtype)
    import pyopencl.array as cla

    check(dc, int(np.prod(shape)) * np.dtype(dtype).itemsize, "a device array")
    return cla.empty(dc.queue, shape, np.dtype(dtype))


def zeros(dc, shape: tuple[int, ...], dtype: object):
    """A zeroed device array (filled on the device: nothing travels)."""
    import pyopencl as cl

    a = empty(dc, shape, dtype, True)
    if a.nbytes:
        with dc.lock:
            cl.enqueue_fill_buffer(dc.queue, a.data, np.zeros(1, np.uint8), 0, a.nbytes)
    return a


def upload(dc, a: np.ndarray):
    """A device copy of host array `a`."""
    import pyopencl.array as cla

    check(dc, a.nbytes, "a device array")
    with dc.lock:
        return cla.to_device(dc.queue, np.ascontiguousarray(a))


def to_host(dc, a):
    """Host array `a` as it is, or device array `a` read back into a new aligned host array."""
    if a is None or not on_device(a):
        return a
    out = recycled_empty(a.shape, a.dtype)
    with dc.lock:
        a.get(queue=dc.queue, ary=out)
    return out


class Reduced:
    """Device array `a` as a mode's `finish_kernel` reads the sums: their shape and size, and
    `max()` reduced on the device (one number comes back, not the sums)."""

    def __init__(self, dc, a) -> None:
        self.dc, self.a = dc, a
        self.shape, self.size, self.dtype = a.shape, a.size, a.dtype

    def max(self):
        """The largest sum (int64 sums): kernels/opencl/sums.cl's max_sums leaves the largest of
        each part of SUMS_PER_PART or more sums (MAX_PARTS at most), the host takes theirs."""
        import pyopencl as cl

        from chronocl.engine.program import kernel

        dc, n = self.dc, self.a.size
        parts = empty(dc, (max(1, min(n // SUMS_PER_PART, MAX_PARTS)),), np.int64, True)
        host = np.empty(parts.shape, np.int64)
        kern = kernel(dc, "sums.cl", "max_sums", {"SLIDING": True, "CHANNELS": 1})
        with dc.lock:
            kern.set_args(self.a.data, np.int64(n), parts.data)
            cl.enqueue_nd_range_kernel(dc.queue, kern, parts.shape, None)
            cl.enqueue_copy(dc.queue, host, parts.data)
        return host.max()


# The device's reduction: work-items enough to fill a GPU, whose maxima come back (128 KB at most).
MAX_PARTS = 16384
SUMS_PER_PART = 64
