"""The read roofline: how fast this machine can merely read a window brick, the ceiling that
integration throughput is compared with (the scalability report, bench/integrate.py).

Two readers of the same xytz brick (Z, W, Y, X) in memory: an OpenCL kernel that reads every
element once and sums over the steps (`kernels/opencl/read_roofline.cl`, as the integration
kernels read), and numpy's max over the brick. The roofline is the faster of the two.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from chronocl.core.memory import aligned_empty
from chronocl.core.timing import race
from chronocl.engine.device import DeviceContext, get_context
from chronocl.engine.program import kernel

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


def read_fns(dc: DeviceContext, brick: np.ndarray) -> dict[str, Callable[[], object]]:
    """{'read-opencl': read the brick on the device of `dc`, 'read-numpy-max': brick.max}.

    The brick is (Z, W, Y, X) float32 or uint8 with X a multiple of VEC (`padded`).
    """
    import pyopencl as cl

    nz, w, ny, nx = brick.shape
    dtype = {"float32": "float", "uint8": "uchar"}[brick.dtype.name]
    defines = {"DATA_T": dtype, "DATA_V": f"{dtype}{VEC}", "LUT_N": 256, "VEC": VEC}
    kern = kernel(dc, "read_roofline.cl", "read_sum", defines)
    out = np.empty((nz, ny, nx), dtype=np.float32)
    mf = cl.mem_flags
    local = (8, 2, 1) if (nx // VEC) % 8 == 0 and ny % 2 == 0 else None

    def run_cl() -> None:
        src = cl.Buffer(dc.context, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=brick)
        dst = cl.Buffer(dc.context, mf.WRITE_ONLY | mf.USE_HOST_PTR, hostbuf=out)
        kern.set_args(src, np.int32(nx), np.int32(ny), np.int32(w), dst)
        cl.enqueue_nd_range_kernel(dc.queue, kern, (nx // VEC, ny, nz), local)
        mapped, _ = cl.enqueue_map_buffer(dc.queue, dst, cl.map_flags.READ, 0, out.shape, out.dtype)
        mapped.base.release(dc.queue)
        dc.queue.finish()

    return {"read-opencl": run_cl, "read-numpy-max": brick.max}


def read_roofline(brick: np.ndarray, device: str | None = None, repeats: int = 3) -> dict:
    """Read rates of `brick` (Z, W, Y, X; float32 or uint8) on `device`: each reader's GB/s,
    and the roofline (the faster) in GB/s and G voxel-steps/s, medians of `repeats` runs."""
    if brick.dtype.name not in ("float32", "uint8"):
        brick = brick.astype(np.float32)
    brick = padded(brick)
    dc = get_context(device)
    with dc.lock:
        times = race(read_fns(dc, brick), repeats)
    rates = {name: brick.nbytes / med / 1e9 for name, (med, _) in times.items()}
    best = max(rates.values())
    return {
        "device": dc.info.index,
        "opencl_read_gb_s": rates["read-opencl"],
        "numpy_read_gb_s": rates["read-numpy-max"],
        "gb_s": best,
        "gvox_steps_s": best / brick.dtype.itemsize,
    }
