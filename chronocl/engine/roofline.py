"""The read roofline: how fast this machine can merely read a window brick, the one bound that
integration throughput is compared with (the scalability report, bench/integrate.py).

The bound is the machine's memory read bandwidth over the same bytes, on every core, used
alone: numpy's max over the xytz brick (Z, W, Y, X) cut along z into one piece per core, the
pieces read side by side (numpy releases the GIL in a reduction), like STREAM's read. An
integration reads every byte at least once, so none can beat it, and a fraction above 1
means the bound is wrong. Where the kernels run on a device apart from host memory (a GPU),
their time includes copying the brick across, and the bound is the slower of the memory read
and the host-to-device copy. That copy is timed as the engine uploads
(`chronocl.engine.transfer.run_chunks`): chunks from pinned staging buffers, two in turn, on
the upload queue; a pageable copy would set a bound the engine beats. An integration of a
window already resident on the device (a `Session` after a TF edit) copies no step: its bound
(`bound_of(..., resident=True)`) is `read-device`, the read kernel over the brick uploaded
once beforehand, with its 4-byte sums per voxel read back (no integration returns less).

The OpenCL read kernel (`kernels/opencl/read_roofline.cl`: every work-item reads its voxels
of every step once and sums them, as the integration kernels read) is measured beside it. On a
device that reads host memory (a CPU device) it is a memory read on every core too, and the
bound is the faster of the two: inside bench/integrate.py's long race numpy's threads once read
3-4 times slower than alone while the kernels did not, and fractions above 1 came out (a bound
below a kernel's own read is no bound). On a GPU its buffers wrap host memory, which the driver
copies across first: there it is reported only.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from chronocl.core.memory import aligned_empty
from chronocl.core.timing import race
from chronocl.core.tuning import TUNING
from chronocl.engine.buffers import DeviceWork, buffer, max_alloc
from chronocl.engine.device import DeviceContext, get_context
from chronocl.engine.device_steps import reserve
from chronocl.engine.program import kernel
from chronocl.engine.transfer import MAX_CHUNK, make_streams

VEC = 16  # voxels along x per work-item of read_sum


def padded(brick: np.ndarray) -> np.ndarray:
    """`brick` with x padded to a multiple of VEC (the kernel reads VEC voxels per work-item)."""
    nx = brick.shape[3]
    if nx % VEC == 0 and brick.flags.c_contiguous:
        return brick
    out = aligned_empty((*brick.shape[:3], -(-nx // VEC) * VEC), brick.dtype)
    out[..., nx:] = 0
    out[..., :nx] = brick
    return out


_pools: dict[int, ThreadPoolExecutor] = {}


def _pool(n: int) -> ThreadPoolExecutor:
    """A pool of `n` threads kept for the process (starting threads is not the read's time)."""
    if n not in _pools:
        _pools[n] = ThreadPoolExecutor(n, thread_name_prefix="chronocl-roofline")
    return _pools[n]


def memory_read_fn(brick: np.ndarray, threads: int | None = None) -> Callable[[], object]:
    """Read every byte of `brick` once on `threads` threads (default: every core): numpy's max over
    pieces of z rows, TUNING.roofline_pieces_per_thread per thread taken in turn by whichever thread
    is free, so that a thread the system delays does not hold up the rest (as PoCL's
    work-groups)."""
    n = max(1, threads or os.cpu_count() or 1)
    cuts = max(1, min(brick.shape[0], n * TUNING.roofline_pieces_per_thread))
    edges = np.linspace(0, brick.shape[0], cuts + 1).round().astype(int)
    pieces = [brick[a:b] for a, b in itertools.pairwise(edges) if b > a]
    if n == 1 or len(pieces) == 1:
        return brick.max
    pool = _pool(n)

    def run() -> list:
        return list(pool.map(np.max, pieces))

    return run


def read_fns(
    dc: DeviceContext, brick: np.ndarray, copy: bool | None = None, chunk_bytes: int = MAX_CHUNK
) -> dict[str, Callable[[], object]]:
    """{'read-memory': numpy's read on every core, 'read-opencl': the read kernel on the device
    of `dc`, and on a device apart from host memory (or with `copy`) 'copy-to-device': the
    brick's bytes uploaded from pinned staging in chunks of `chunk_bytes`, as the engine
    uploads, and where the brick fits what is left of the device's budget for resident steps
    (`device_steps.reserve`, held while the reader lives) 'read-device': the read kernel over
    the brick uploaded once}; `bound_of` picks the bound from their rates.

    The brick is (Z, W, Y, X) float32 or uint8 with X a multiple of VEC (`padded`).
    """
    nz, _, ny, nx = brick.shape
    dtype = {"float32": "float", "uint8": "uchar"}[brick.dtype.name]
    defines = {"DATA_T": dtype, "DATA_V": f"{dtype}{VEC}", "LUT_N": 256, "VEC": VEC}
    kern = kernel(dc, "read_roofline.cl", "read_sum", defines)
    local = (8, 2, 1) if (nx // VEC) % 8 == 0 and ny % 2 == 0 else None

    # z rows one buffer may hold: a brick over the device's largest allocation is read in
    # chunks of rows, as the engine reads it
    rows = max(1, min(nz, max_alloc(dc) // max(1, brick[:1].nbytes)))
    fns = {
        "read-memory": memory_read_fn(brick),
        "read-opencl": kernel_read_fn(dc, brick, kern, local, rows),
    }
    if copy if copy is not None else not dc.is_cpu:
        fns["copy-to-device"] = pinned_copy_fn(dc, brick, min(chunk_bytes, max_alloc(dc)))
        hold = reserve(dc, brick.nbytes)  # counted against the sessions' steps on the device
        if hold is not None:
            fns["read-device"] = kernel_read_fn(dc, brick, kern, local, rows, resident=True)
            fns["read-device"].hold = hold  # given back when the reader goes
    return fns


def kernel_read_fn(dc: DeviceContext, brick: np.ndarray, kern, local, rows: int, resident=False):
    """The read kernel over `brick` in buffers of `rows` z rows, each voxel's sum over the
    steps read back into `fn.sums`: buffers wrapping the host's brick at each call or, with
    `resident`, copies on the device uploaded once here, before any timing (as a session keeps
    its window there; the 4 bytes a voxel read back are no more than any integration's)."""
    import pyopencl as cl

    nz, w, ny, nx = brick.shape
    out = np.empty((nz, ny, nx), dtype=np.float32)
    cuts = [(a, min(nz, a + rows)) for a in range(0, nz, rows)]
    uploaded = [buffer(dc, brick[a:b]) for a, b in cuts] if resident else None

    def run() -> None:
        with DeviceWork(dc) as work:
            for i, (a, b) in enumerate(cuts):
                src = uploaded[i] if uploaded else work.buffer(brick[a:b], in_place=True)
                dst = work.buffer(out[a:b], access="w", in_place=True)
                kern.set_args(src, np.int32(nx), np.int32(ny), np.int32(w), dst)
                cl.enqueue_nd_range_kernel(dc.queue, kern, (nx // VEC, ny, b - a), local)
                work.read(out[a:b], dst, in_place=True)

    run.sums = out
    return run


def pinned_copy_fn(dc: DeviceContext, brick: np.ndarray, chunk_bytes: int) -> Callable[[], None]:
    """Upload `brick.nbytes` bytes to the device of `dc` as `run_chunks` does: chunks of
    `chunk_bytes` from two pinned staging buffers in turn (each holding a chunk of the brick,
    filled once: the host's copy into staging is the memory read's part of the bound) into two
    device buffers, on an upload queue of their own. `fn.staged` and `fn.device` are the
    staging and device buffers (tests read back what crossed)."""
    import pyopencl as cl

    data = brick.reshape(-1).view(np.uint8)
    size = max(1, min(data.size, chunk_bytes))
    streams = make_streams(dc.context, dc.device)
    slots = 2 if data.size > size else 1
    staged = [streams.staging(dc, f"stage{k}", size) for k in range(slots)]
    device = [streams.buffer(dc, f"in{k}", size, "r") for k in range(slots)]
    for k in range(slots):
        part = data[k * size : (k + 1) * size]
        staged[k][: part.size] = part

    def copy() -> None:
        with DeviceWork(dc) as work:
            work.queues.append(streams.upload)
            for j, a in enumerate(range(0, data.size, size)):
                n = min(size, data.size - a)
                cl.enqueue_copy(
                    streams.upload, device[j % slots], staged[j % slots][:n], is_blocking=False
                )

    copy.staged, copy.device, copy.streams = staged, device, streams
    return copy


def bound_of(rates: dict[str, float], resident: bool = False) -> tuple[str, float]:
    """(what limits, GB/s) from read_fns' rates: the memory read on every core (where the device
    reads host memory, no copy to it measured: the faster of numpy's and the OpenCL read
    kernel's), or the copy to the device where there is one and it is slower. With `resident`
    (the window already on the device, no step copied), where the device read was measured:
    that read."""
    if resident and "read-device" in rates:
        return ("read-device", rates["read-device"])
    memory = rates["read-memory"]
    if "copy-to-device" not in rates:
        memory = max(memory, rates.get("read-opencl", 0.0))
    copy = rates.get("copy-to-device", np.inf)
    return ("copy-to-device", copy) if copy < memory else ("read-memory", memory)


LIMITS = {
    "read-memory": "memory read on every core",
    "copy-to-device": "copy from host to device (pinned staging, as the engine uploads)",
    "read-device": "device read of a window resident there (its sums read back)",
}


def read_roofline(brick: np.ndarray, device: str | None = None, repeats: int = 3) -> dict:
    """Read rates of `brick` (Z, W, Y, X; float32 or uint8) on `device`, medians of `repeats`
    runs: the memory read on every core, the OpenCL read kernel, the copy to a GPU, and the
    bound (`bound_of`, what limits) in GB/s and G voxel-steps/s."""
    if brick.dtype.name not in ("float32", "uint8"):
        brick = brick.astype(np.float32)
    brick = padded(brick)
    dc = get_context(device)
    # no lock here: each device reader holds the device's (non-reentrant) lock itself
    # (`chronocl.engine.buffers.DeviceWork`); holding it around them deadlocked
    times = race(read_fns(dc, brick), repeats)
    rates = {name: brick.nbytes / med / 1e9 for name, (med, _) in times.items()}
    limit, best = bound_of(rates)
    return {
        "device": dc.info.index,
        "memory_read_gb_s": rates["read-memory"],
        "memory_read_threads": os.cpu_count() or 1,
        "opencl_read_gb_s": rates["read-opencl"],
        "copy_to_device_gb_s": rates.get("copy-to-device"),
        "device_read_gb_s": rates.get("read-device"),
        "limit": LIMITS[limit],
        "gb_s": best,
        "gvox_steps_s": best / brick.dtype.itemsize,
    }
