"""Each voxel's winner of an integrated window gathered from its steps: the index of the step
that won (k) and the value it won with (u; change: the change δ), for recolouring a TF edit
(`chronocl.integration.interactive.winners`). The engines' `gather`: numpy's on the host threads
(`on_host`, reading every step) and OpenCL's (`on_device`, kernels/opencl/recolour_gather.cl:
each voxel reads its winning step's value alone), equal bit for bit.

Both map a voxel's t_index t (the selected step, -1: none) through one index table,
`table[t + 1]` (`index_table`). On a CPU device the steps and the winners are read and written
where they lie (host pointers, nothing copied); on a GPU the steps are copied to it and the
winners only back (`_written`). The kernels are built without common.h.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from chronocl.core import host_threads
from chronocl.core import values as _values
from chronocl.core.interrupt import checkpoint, watched
from chronocl.core.memory import ALIGN, aligned_empty, is_aligned, recycled_empty
from chronocl.core.tuning import TUNING

CHUNK = 8  # steps per gather pass (the kernel's p1..p8)
CL_TYPES = {  # numpy's name -> OpenCL's, for the raw values the gather reads
    "float32": "float",
    "float64": "double",
    "uint8": "uchar",
    "uint16": "ushort",
    "int16": "short",
    "int32": "int",
}


def index_type(k_dtype) -> str:
    """OpenCL's type of the winners' step indices (uint8 or uint16)."""
    return "uchar" if np.dtype(k_dtype) == np.uint8 else "ushort"


def gather_defines(k_dtype, dtype, change: bool) -> dict[str, object]:
    """The -D options of kernels/opencl/recolour_gather.cl for raw values of `dtype`."""
    return {"K_T": index_type(k_dtype), "V_T": CL_TYPES[np.dtype(dtype).name], "CHANGE": change}


def index_table(steps: tuple[int, ...]) -> np.ndarray:
    """Each voxel's winner index from its t_index t (the selected step, -1: none): `table[t + 1]`,
    the window's place of step t (uint8, uint16 from 255 steps), or `none` (the dtype's largest)
    where t is -1 or no step of the window. Both gathers read it so."""
    dtype = np.uint8 if len(steps) < 255 else np.uint16
    table = np.full(max(steps) + 2, np.iinfo(dtype).max, dtype=dtype)
    table[np.asarray(steps) + 1] = np.arange(len(steps), dtype=dtype)
    return table


def on_host(
    t_index: np.ndarray,
    arrays: dict[int, np.ndarray],
    steps: tuple[int, ...],
    value_range: tuple[float, float],
    change: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """(u, k) of an integrated window from its t_index and the window's raw resident values
    (step -> (Z, Y, X)), gathered on the host threads slab by slab, reading every step. Work
    that may be given up (`watched`) runs in `TUNING.gather_pieces` groups of slabs, each
    finished before the checkpoint after it, as `on_device`'s slabs are."""
    table = index_table(steps)
    u = recycled_empty(t_index.shape, np.float32)  # aligned: OpenCL reads them in place
    k = recycled_empty(t_index.shape, table.dtype)
    nz, pieces = t_index.shape[0], TUNING.gather_pieces if watched() else 1
    # 4 slabs a thread, and where given up, enough that each piece keeps every thread busy
    count = max(4, pieces) * host_threads.workers()
    cuts = np.linspace(0, nz, min(nz, count) + 1).astype(int)
    slabs = [(int(a), int(b)) for a, b in itertools.pairwise(cuts.tolist()) if b > a]
    per = -(-len(slabs) // pieces)
    args = (t_index, arrays, steps, value_range, change, table, u, k)
    for i in range(0, len(slabs), per):
        group = slabs[i : i + per]
        for job in [host_threads.pool().submit(_host_slab, *args, a, b) for a, b in group]:
            job.result()
        if group[-1][1] < nz:
            checkpoint("preparing the recolouring", group[-1][1], nz)
    return u, k


def _host_slab(t_index, arrays, steps, value_range, change, table, u, k, z0: int, z1: int):
    kk = k[z0:z1]
    np.take(table, np.add(t_index[z0:z1], 1, dtype=np.intp), out=kk)  # take's own index type
    raw = u[z0:z1]
    raw[...] = 0
    if change:
        before = np.zeros_like(raw)
    for i, s in enumerate(steps):
        if i == 0 and change:
            continue  # step 0 of the window starts no change
        where = kk == i
        if not where.any():
            continue
        np.copyto(raw, arrays[s][z0:z1], where=where, casting="unsafe")
        if change:
            np.copyto(before, arrays[steps[i - 1]][z0:z1], where=where, casting="unsafe")
    if change:
        lo, hi = _values.clip_bounds(*value_range)
        _, scale = _values.normalization(*value_range)
        d = np.abs(np.clip(raw, lo, hi) - np.clip(before, lo, hi))
        raw[...] = np.minimum(d * scale, np.float32(1.0))
    else:
        raw[...] = _values.normalize(raw, *value_range)


def on_device(
    dc,
    t_index: np.ndarray,
    arrays: dict[int, np.ndarray],
    steps: tuple[int, ...],
    value_range: tuple[float, float],
    change: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """`on_host` on the OpenCL device `dc` (a `DeviceContext`): each voxel reads its winning
    step's value alone, in place on a CPU device, in slabs of z rows whose buffers each fit
    the device's largest (`chronocl.engine.buffers`). Falls back to `on_host` for data types
    the kernel does not take, and for steps it would have to copy."""
    import pyopencl as cl

    from chronocl.engine.buffers import DeviceWork, max_alloc
    from chronocl.engine.program import build

    dtype = np.dtype(arrays[steps[0]].dtype)
    if dtype.name not in CL_TYPES or any(arrays[s].dtype != dtype for s in steps):
        return on_host(t_index, arrays, steps, value_range, change)
    limit = max_alloc(dc)
    nz, ny, nx = shape = t_index.shape
    plane = ny * nx  # voxels of one z row
    per_voxel = max(4, dtype.itemsize)  # t_index and u: 4 bytes a voxel; a step's value
    block = _block(arrays, steps)
    rows = limit // (plane * per_voxel)
    if block is not None:
        _, offs, sz = block
        fixed = ALIGN + (int(offs.max() - offs.min()) + plane) * dtype.itemsize  # 1 row's slab
        rows = min(rows, 1 + (limit - fixed) // (sz * dtype.itemsize) if limit >= fixed else 0)
        if rows < 1:
            block = None  # a slab of one row would not fit in one buffer: step by step
            rows = limit // (plane * per_voxel)
    aligned_rows = ALIGN // math.gcd(plane, ALIGN)
    if watched():  # in pieces, each a checkpoint
        rows = min(rows, max(aligned_rows, -(-nz // TUNING.gather_pieces)))
    if rows < nz:  # slabs start aligned, as PoCL uses host memory in place (k: 1 byte a voxel)
        rows -= rows % aligned_rows
    in_place = all(arrays[s].flags.c_contiguous and is_aligned(arrays[s]) for s in steps)
    if (block is None and not in_place) or rows < 1:  # a copy costs more than numpy's gather
        return on_host(t_index, arrays, steps, value_range, change)
    table = index_table(steps)
    k_dtype, none = table.dtype, int(np.iinfo(table.dtype).max)
    # PoCL reads and writes aligned host memory in place; the kernels write every voxel, on
    # the memory of winners that died where there is some (at 512^3 fresh pages and zeroing
    # them cost 0.6 s of a 1.7 s gather here)
    u = recycled_empty(shape, np.float32)
    k = recycled_empty(shape, k_dtype)
    t_index = aligned(t_index.astype(np.int32, copy=False))
    cpu = dc.is_cpu
    program = build(dc, "recolour_gather.cl", gather_defines(k_dtype, dtype, change), common=False)
    lo, hi = _values.clip_bounds(*value_range)
    vmin, scale = _values.normalization(*value_range)
    values = (np.float32(lo if change else vmin), np.float32(hi), np.float32(scale))
    first = 1 if change else 0  # change: the window's first step starts no change
    slabs = [(z0, min(nz, z0 + rows)) for z0 in range(0, nz, max(1, rows))]
    # A gather that may be given up holds the device's lock a slab at a time: other clients'
    # frames run between its slabs, and its input is looked at after each.
    groups = [[slab] for slab in slabs] if watched() else [slabs]
    for group in groups:
        # work that reads and writes host memory finishes before anything here can be freed
        with DeviceWork(dc) as work:
            table_buf = work.buffer(table)
            for z0, z1 in group:
                n = (z1 - z0) * plane
                k_buf, u_buf = (_written(work, a[z0:z1], cpu) for a in (k, u))
                index_args = (work.buffer(t_index[z0:z1], in_place=cpu), table_buf, k_buf, u_buf)
                if block is not None:
                    data, offs_buf = _slab(work, block, z0, z1, dtype.itemsize, plane, cpu)
                    kern = cl.Kernel(program, "gather_block")
                    kern.set_args(
                        *index_args, data, offs_buf, np.int64(block[2]), np.uint32(none), *values
                    )
                    cl.enqueue_nd_range_kernel(dc.queue, kern, (plane, z1 - z0), None)
                else:
                    index = cl.Kernel(program, "window_index")
                    index.set_args(*index_args)
                    cl.enqueue_nd_range_kernel(dc.queue, index, (n,), None)
                    bufs = {s: work.buffer(arrays[s][z0:z1], in_place=cpu) for s in steps}
                    for base in range(first, len(steps), CHUNK):
                        count = min(CHUNK, len(steps) - base)
                        ptrs = [bufs[steps[max(base - 1, 0)]]]
                        ptrs += [bufs[steps[min(base + j, len(steps) - 1)]] for j in range(CHUNK)]
                        kern = cl.Kernel(program, "gather")
                        kern.set_args(
                            k_buf, u_buf, np.uint32(base), np.uint32(count), *ptrs, *values
                        )  # fmt: skip
                        cl.enqueue_nd_range_kernel(dc.queue, kern, (n,), None)
                work.read(k[z0:z1], k_buf, cpu)
                work.read(u[z0:z1], u_buf, cpu)
        if group[-1][1] < nz:
            checkpoint("preparing the recolouring", group[-1][1], nz)
    return u, k


def _written(work, out: np.ndarray, cpu: bool):
    """The buffer of `out`, whose every voxel the kernels write: `out` itself on a CPU device,
    else one of its size left uninitialised (nothing of `out`'s memory, uninitialised too, is
    copied to the device: at 512^3 u and k are 640 MB)."""
    if cpu:
        return work.buffer(out, access="rw", in_place=True)
    return work.buffer(nbytes=out.nbytes, access="rw")


def _slab(work, block: tuple, z0: int, z1: int, item: int, plane: int, cpu: bool):
    """The buffer of the part of the slot block that z rows z0..z1 of every step lie in (from
    an aligned address; `plane`: elements one z row of a step spans) and each step's element
    offset in it."""
    base, offs, sz = block
    first = (int(offs.min()) + z0 * sz) * item  # bytes from the block's start
    start = first - first % ALIGN
    stop = (int(offs.max()) + (z1 - 1) * sz + plane) * item
    local = (offs + z0 * sz - start // item).astype(np.int64)
    return work.buffer(base[start:stop], in_place=cpu), work.buffer(local)


def aligned(a: np.ndarray) -> np.ndarray:
    """`a` where PoCL can use it in place (C-contiguous, 64-byte aligned), else a copy."""
    if a.flags.c_contiguous and is_aligned(a):
        return a
    out = aligned_empty(a.shape, a.dtype)
    out[...] = a
    return out


def _block(arrays: dict[int, np.ndarray], steps) -> tuple | None:
    """(a 64-byte aligned byte view of the block, element offset of each window step in it,
    the element stride of their z rows) where the steps are views of one C-contiguous block
    with the same strides, each z row of Y x X contiguous (the window manager's slots), else
    None."""
    views = [arrays[s] for s in steps]
    owners = []
    for a in views:
        while isinstance(a.base, np.ndarray):
            a = a.base
        owners.append(a)
    owner, item, strides = owners[0], views[0].dtype.itemsize, views[0].strides
    if any(o is not owner for o in owners) or not owner.flags.c_contiguous:
        return None
    _, ny, nx = views[0].shape
    rows = strides[2] == item and (ny == 1 or strides[1] == nx * item)
    if not rows or any(v.strides != strides for v in views) or strides[0] % item or strides[0] < 0:
        return None
    first = min(v.ctypes.data for v in views)
    start = first - first % ALIGN  # the block from an aligned address: read in place
    if start < owner.ctypes.data:
        return None
    base = owner.reshape(-1).view(np.uint8)[start - owner.ctypes.data :]
    offsets = [v.ctypes.data - start for v in views]
    if any(o % item for o in offsets):
        return None
    offs = np.array([o // item for o in offsets], dtype=np.int64)
    return base, offs, strides[0] // item
