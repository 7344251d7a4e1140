"""The sliding windows' kernels on an OpenCL device, one voxel per work-item, and read-back.

A window that slides by aggregation combines the partials of adjacent runs of steps
(`combine`); one that slides by inversion keeps fixed-point sums (`fixed_add`) and finishes
them (`finish_sums`). Each runs a mode's kernel built with SLIDING (kernels/opencl/MODE.cl)
whose arguments are its inputs, tables, outputs, then scalars; buffers and the wait for the
kernels come from `chronocl.engine.buffers`.

Every array may be a host (numpy) or a device array (`chronocl.engine.device_arrays`): device
arrays are passed as their buffers, copied neither way, and partials combined from device
arrays are made on the device, so a window's sliding state can stay there between slides (a
GPU's); `finish_sums` always returns a host array, the one thing a slide reads back.
"""

from __future__ import annotations

import numpy as np

from chronocl.engine.buffers import DeviceLimitError, DeviceWork, max_alloc, spans
from chronocl.engine.device import DeviceContext
from chronocl.engine.device_arrays import Reduced, empty, on_device
from chronocl.engine.program import kernel
from chronocl.modes.base import Partial
from chronocl.modes.spec import IntegrationSpec

# Work-items in a group of these kernels, whatever the volume: a driver compiles a kernel once
# per group size (PoCL: a work-group function each), and left to choose it picks a divisor of
# each volume's size; the suite's odd shapes made PoCL compile combine_extreme 31 times.
ELEMENT_GROUP = 64


def combine(
    dc: DeviceContext,
    host_ptr: bool,
    front: Partial,
    back: Partial,
    spec: IntegrationSpec,
    rgba8: bool = False,
) -> Partial:
    """The partial of `front` then `back` (see the mode's `combine`); new arrays, on the device
    where `front`'s are. With `rgba8` (a mode combining partials), its colour in the display
    format, RGBA8 by the host conversion's rule (kernels/opencl/rgba8.h): a final value only,
    never combined again."""
    mode = spec.integration
    file, function, defines = mode.combine_kernel(spec)
    shape, device = front.rgba.shape, on_device(front.rgba)
    if mode.slides == "invert":  # the aggregated opacity alone
        out = empty(dc, shape, np.float32, device)
        ins = [front.rgba, back.rgba]
        run(dc, host_ptr, mode.kernel, function, front.rgba.size, defines, ins, [out])
        return Partial(out, None)
    rgba = empty(dc, shape, np.uint8 if rgba8 else np.float32, device)
    defines = {**defines, "OUT8": rgba8}
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
    ins = [acc, *([alpha] if alpha is not None else [])]
    n = t_size(out.shape)
    run(dc, host_ptr, mode.kernel, function, n, defines, ins, [out], scalars, tables=extra)
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
    tables: list[np.ndarray] = (),
) -> None:
    """Run a one-voxel-per-work-item kernel of kernels/opencl/FILE.cl over `n` voxels.

    Kernel arguments are inputs, tables, outputs, scalars; inputs and outputs hold `n` voxels
    (each (n, ...) or (Z, Y, X, ...)), tables are whole (count's LUT); `inout` outputs are read
    too. `host_ptr`: buffers wrap the host arrays (CPU devices) instead of copying. Device
    arrays are their own buffers: nothing is copied to them, nor read back from them. Host
    arrays go in spans of voxels whose buffers each fit the device's largest.
    """
    import pyopencl as cl

    voxels = [*inputs, *outputs]
    item = max(a.nbytes // max(1, n) for a in voxels)
    cuts = spans(n, item, max_alloc(dc))
    if len(cuts) > 1 and any(on_device(a) for a in voxels):
        raise DeviceLimitError("a device array over the device's largest buffer")
    kern = kernel(dc, f"{file}.cl", function, {**defines, "SLIDING": True})
    info = cl.kernel_work_group_info.WORK_GROUP_SIZE  # a small device's may be less
    group = min(ELEMENT_GROUP, int(kern.get_work_group_info(info, dc.device)))
    access = "rw" if inout else "w"
    with DeviceWork(dc) as work:
        held = [work.buffer(a) for a in tables]
        for a, b in cuts:

            def part(x: np.ndarray, a: int = a, b: int = b) -> np.ndarray:
                return x if len(cuts) == 1 else x.reshape(n, -1)[a:b]

            ins = [
                x.data if on_device(x) else work.buffer(part(x), in_place=host_ptr) for x in inputs
            ]
            outs = [
                x.data if on_device(x) else work.buffer(part(x), access=access, in_place=host_ptr)
                for x in outputs
            ]
            kern.set_args(*ins, *held, *outs, *scalars, np.uint64(b - a))
            launch = -(-(b - a) // group) * group  # whole groups (common.h's ELEMENT)
            cl.enqueue_nd_range_kernel(dc.queue, kern, (launch,), (group,))
            # device outputs are used where they are: the in-order queue runs them first
            for x, buf in zip(outputs, outs, strict=True):
                if not on_device(x):
                    work.read(part(x), buf, in_place=host_ptr)


def t_size(rgba_shape: tuple) -> int:
    """Voxels of an RGBA array shape (..., 4)."""
    return int(np.prod(rgba_shape[:-1]))
