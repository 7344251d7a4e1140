"""A sliding window's leaves made on the device, for engines that copy bricks (a GPU).

A leaf (one step, or change's pair) is integrated from the steps resident on the device
(`chronocl.engine.device_steps.DeviceBrick`) into device arrays, and what its combine compares
(`Mode.leaf_value`) is computed there too (kernels/opencl/leaves.cl): nothing of it travels. A
leaf whose steps are on the host (a window over the device budget) is integrated from them and
its partial sent up once. `alpha_of` takes an inverting mode's aggregated opacity on the device.
"""

from __future__ import annotations

import numpy as np

from chronocl.engine.buffers import DeviceWork
from chronocl.engine.defines import DEVICE_TYPES, HALF_DEFINES
from chronocl.engine.device_arrays import empty, upload
from chronocl.engine.device_steps import DeviceBrick
from chronocl.engine.program import kernel
from chronocl.modes.base import Partial, Values


def leaf(engine, brick, steps, positions, spec, value_range: tuple, raw: bool) -> Partial:
    """The partial of `steps` (a whole leaf: every row of `brick`, resident on the device or
    a host brick) in device arrays; `raw` as `accumulate`'s."""
    dc, nz = engine.dc, brick.shape[0]
    order = np.arange(len(steps))
    out = None
    if isinstance(brick, DeviceBrick):  # written on the device, not read back
        _, _, ny, nx = brick.shape
        t_index = empty(dc, (nz, ny, nx), np.int32, True) if spec.has_t_index else None
        out = (empty(dc, (nz, ny, nx, 4), np.float32, True), t_index)
    partial, _ = engine.accumulate(
        brick, slice(0, nz), steps, positions, order, spec, value_range, out=out, raw=raw
    )
    if out is None:  # integrated from the host: sent up once
        t_index = None if partial.t_index is None else upload(dc, partial.t_index)
        partial = Partial(upload(dc, partial.rgba), t_index)
    return partial


def leaf_value(dc, mode, brick, arrays: list[np.ndarray], value_range: tuple):
    """`mode.leaf_value` of a leaf's steps as a device array: from `brick` where it is resident
    (kernels/opencl/leaves.cl), else from the host `arrays` and sent up."""
    if not isinstance(brick, DeviceBrick):
        return upload(dc, mode.leaf_value(Values(np.stack(arrays), value_range)))
    import pyopencl as cl

    nz, w, ny, nx = brick.shape
    out = empty(dc, (nz, ny, nx), np.float32, True)
    function, scalars = mode.leaf_value_kernel(value_range)
    dt = np.dtype(brick.dtype)
    defines = HALF_DEFINES if dt == np.float16 else {"DATA_T": DEVICE_TYPES[dt.name]}
    kern = kernel(dc, "leaves.cl", function, {**defines, "SLIDING": True})
    args = [np.int64(brick.zstride), np.int64(ny * nx), np.int32(w - 1)]
    with DeviceWork(dc) as work:
        kern.set_args(brick.buffer, work.buffer(brick.offsets), *args, out.data, *scalars)
        cl.enqueue_nd_range_kernel(dc.queue, kern, (out.size,), None)
    return out


def alpha_of(dc, rgba):
    """The opacity channel of device array `rgba` (Z, Y, X, 4), a device array."""
    import pyopencl as cl

    alpha = empty(dc, rgba.shape[:-1], np.float32, True)
    kern = kernel(dc, "sums.cl", "alpha_of", {"SLIDING": True, "CHANNELS": 1})
    with DeviceWork(dc):
        kern.set_args(rgba.data, alpha.data)
        cl.enqueue_nd_range_kernel(dc.queue, kern, (alpha.size,), None)
    return alpha
