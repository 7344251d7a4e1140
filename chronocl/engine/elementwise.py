"""The sliding windows' kernels on an OpenCL device, one voxel per work-item, and read-back.

A window that slides by aggregation combines the partials of adjacent runs of steps
(`combine`); one that slides by inversion keeps fixed-point sums (`fixed_add`) and finishes
them (`finish_sums`). Each runs a mode's kernel built with SLIDING (kernels/opencl/MODE.cl)
whose arguments are its inputs, outputs, then scalars. `read_back` makes host arrays hold
what kernels wrote, for these and for `chronocl.engine.opencl`'s integrate kernels.

Every array may be a host (numpy) or a device array (`chronocl.engine.device_arrays`): device
arrays are passed as their buffers, copied neither way, and partials combined from device
arrays are made on the device, so a window's sliding state can stay there between slides (a
GPU's); `finish_sums` always returns a host array, the one thing a slide reads back.
"""

from __future__ import annotations

import numpy as np

from chronocl.engine.device import DeviceContext
from chronocl.engine.device_arrays import Reduced, empty, on_device
from chronocl.engine.program import kernel
from chronocl.modes.base import Partial
from chronocl.modes.spec import IntegrationSpec


def combine(
    dc: DeviceContext, host_ptr: bool, front: Partial, back: Partial, spec: IntegrationSpec
) -> Partial:
    """The partial of `front` then `back` (see the mode's `combine`); new arrays, on the device
    where `front`'s are."""
    mode = spec.integration
    file, function, defines = mode.combine_kernel(spec)
    shape, device = front.rgba.shape, on_device(front.rgba)
    if mode.slides == "invert":  # the aggregated opacity alone
        out = empty(dc, shape, np.float32, device)
        ins = [front.rgba, back.rgba]
        run(dc, host_ptr, mode.kernel, function, front.rgba.size, defines, ins, [out])
        return Partial(out, None)
    rgba = empty(dc, shape, np.float32, device)
    t_index = empty(dc, shape[:-1], np.int32, device) if mode.has_t_index else None
    value = empty(dc, shape[:-1], np.float32, device) if front.value is not None else None
    ins = [a for p in (front, back) for a in (p.rgba, p.t_index, p.value) if a is not None]
    outs = [a for a in (rgba, t_index, value) if a is not None]
    run(dc, host_ptr, file, function, t_size(shape), defines, ins, outs)
    return Partial(rgba, t_index, value)


def fixed_add(dc: DeviceContext, host_ptr: bool, acc: np.ndarray, rgba: np.ndarray, sign: int):
    """acc (Z, Y, X, C) int64 += sign * fixed-point first C channels of a raw partial."""
    defines = {"CHANNELS": acc.shape[-1]}
    n = rgba.size // 4
    run(dc, host_ptr, "sums", "fixed_add", n, defines, [rgba], [acc], [np.int32(sign)], inout=True)


def finish_sums(
    dc: DeviceContext,
    host_ptr: bool,
    acc: np.ndarray,
    alpha: np.ndarray | None,
    positions: np.ndarray,
    spec: IntegrationSpec,
) -> np.ndarray:
    """The finished RGBA of a window kept as fixed-point sums (see Mode.finish_sums), a host
    array (sums and opacity on the device stay there)."""
    mode = spec.integration
    sums = Reduced(dc, acc) if on_device(acc) else acc
    function, defines, extra, scalars = mode.finish_kernel(sums, positions, spec)
    out = empty(dc, (*acc.shape[:-1], 4), np.float32, False)
    ins = [acc, *([alpha] if alpha is not None else []), *extra]
    run(dc, host_ptr, mode.kernel, function, t_size(out.shape), defines, ins, [out], scalars)
    return out


def run(
    dc: DeviceContext,
    host_ptr: bool,
    file: str,
    function: str,
    n: int,
    defines: dict,
    inputs: list[np.ndarray],
    outputs: list[np.ndarray],
    scalars: list = (),
    inout: bool = False,
) -> None:
    """Run a one-voxel-per-work-item kernel of kernels/opencl/FILE.cl over `n` voxels.

    Kernel arguments are inputs, outputs, scalars; `inout` outputs are read too.
    `host_ptr`: buffers wrap the host arrays (CPU devices) instead of copying. Device arrays
    are their own buffers: nothing is copied to them, nor read back from them.
    """
    import pyopencl as cl

    ctx, mf = dc.context, cl.mem_flags
    host = mf.USE_HOST_PTR if host_ptr else mf.COPY_HOST_PTR
    flag = mf.READ_WRITE if inout else mf.WRITE_ONLY

    def buffer(a: np.ndarray, output: bool):
        if on_device(a):
            return a.data
        if not output:
            return cl.Buffer(ctx, mf.READ_ONLY | host, hostbuf=np.ascontiguousarray(a))
        if host_ptr or inout:
            return cl.Buffer(ctx, flag | host, hostbuf=a)
        return cl.Buffer(ctx, flag, a.nbytes)

    ins = [buffer(a, False) for a in inputs]
    outs = [buffer(a, True) for a in outputs]
    back = [(a, b) for a, b in zip(outputs, outs, strict=True) if not on_device(a)]
    kern = kernel(dc, f"{file}.cl", function, {**defines, "SLIDING": True})
    with dc.lock:
        kern.set_args(*ins, *outs, *scalars)
        cl.enqueue_nd_range_kernel(dc.queue, kern, (n,), None)
        if back:  # device outputs are used where they are: the in-order queue runs them first
            read_back(dc, host_ptr, [a for a, _ in back], [b for _, b in back])


def read_back(dc: DeviceContext, host_ptr: bool, outputs: list[np.ndarray], bufs: list) -> None:
    """Make the host arrays hold the kernels' results, then wait (dc's lock is held)."""
    import pyopencl as cl

    queue = dc.queue
    # Enqueued without waiting (the queue runs in order), then one wait for them all:
    # each blocking call cost a round trip through the driver's threads (max 1.3 % faster).
    for a, buf in zip(outputs, bufs, strict=True):
        if host_ptr:
            # Mapping synchronises the host array (no copy on CPU devices).
            mapped, _ = cl.enqueue_map_buffer(
                queue, buf, cl.map_flags.READ, 0, a.shape, a.dtype, is_blocking=False
            )
            mapped.base.release(queue)
        else:
            cl.enqueue_copy(queue, a, buf, is_blocking=False)
    queue.finish()


def t_size(rgba_shape: tuple) -> int:
    """Voxels of an RGBA array shape (..., 4)."""
    return int(np.prod(rgba_shape[:-1]))
