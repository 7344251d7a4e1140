"""The OpenCL integration engine: one z-slab brick in, the slab's chronovolume part out.

Transfer-function work per step is done once on the host: a per-step LUT of
data TF x time colour/alpha, so a kernel does one lookup per voxel-step
(quantised uint8 data index their LUT directly). Bricks are in xytz order
(rows, W, Y, X). On CPU devices buffers wrap the host arrays
(CL_MEM_USE_HOST_PTR) instead of copying; on GPUs data are copied.
"""

from __future__ import annotations

import numpy as np

from .. import reference
from ..reference import Partial
from ..spec import IntegrationSpec
from ..tf import lut_lookup
from .device import DeviceContext, get_context
from .program import kernel

DEVICE_TYPES = {"uint8": "uchar", "uint16": "ushort", "int16": "short", "float32": "float"}
KERNELS = {
    "alpha": ("alpha.cl", "integrate_alpha"),
    "first_hit": ("first_hit.cl", "integrate_first_hit"),
    "additive": ("additive.cl", "integrate_additive"),
    "max": ("extreme.cl", "integrate_extreme"),
    "min": ("extreme.cl", "integrate_extreme"),
}
ENHANCE_CODES = {"none": 0, "edge": 1, "silhouette": 2}


def device_dtype(dtype: np.dtype) -> np.dtype:
    """The dtype a brick is given to the device in (float64 goes as float32, like the reference)."""
    return np.dtype(np.float32) if np.dtype(dtype) == np.float64 else np.dtype(dtype)


class OpenCLEngine:
    """Integrates xytz bricks on one OpenCL device.

    `host_ptr`, `early_exit` and `quantized` switch the fast paths (default: host
    pointers on CPU devices, early exit on, direct LUT indexing for uint8); tests
    check each against the general path.
    """

    name = "opencl"

    def __init__(
        self,
        device: str | None = None,
        *,
        host_ptr: bool | None = None,
        early_exit: bool = True,
        quantized: bool = True,
        local_size: tuple[int, int, int] | None = None,
        max_brick_bytes: int | None = None,
    ) -> None:
        self.dc: DeviceContext = get_context(device)
        self.host_ptr = self.dc.is_cpu if host_ptr is None else host_ptr
        self.early_exit = early_exit
        self.quantized = quantized
        self.local_size = local_size
        self._max_brick = max_brick_bytes

    @property
    def max_brick_bytes(self) -> int:
        """Largest brick one buffer may hold on this device (or the limit given)."""
        device = min(self.dc.info.max_alloc, self.dc.info.global_mem // 4)
        return int(device if self._max_brick is None else min(device, self._max_brick))

    def step_lut(
        self,
        spec: IntegrationSpec,
        positions: np.ndarray,
        quant: bool,
        value_range: tuple[float, float],
    ) -> np.ndarray:
        """(W * N, 4) float32: per step k, (rgb_d * rgb_t(p_k), a_d * a_t(p_k)) over N entries.

        Quantised: N = 256 entries at the exact normalised value of each byte value.
        """
        rgb_t, a_t = spec.time_tf.evaluate(positions)
        scale = np.concatenate([rgb_t, a_t[:, None]], axis=1)  # (W, 4)
        if quant:
            u = reference.normalize(np.arange(256, dtype=np.uint8), *value_range)
            base = lut_lookup(spec.data_tf.lut, u)  # float64 like the reference
        else:
            base = spec.data_tf.lut.astype(np.float64)
        return (base[None, :, :] * scale[:, None, :]).astype(np.float32).reshape(-1, 4)

    def accumulate(
        self,
        brick: np.ndarray,
        crop: slice,
        steps: np.ndarray | tuple[int, ...],
        positions: np.ndarray,
        order: np.ndarray,
        spec: IntegrationSpec,
        value_range: tuple[float, float],
    ) -> tuple[Partial, bool]:
        """Integrate brick rows `crop` of an xytz brick (rows, W, Y, X).

        Returns the partial result and whether it is final (additive normalised by the
        time TF is finished on the device; normalisation by the volume maximum is global).
        """
        import pyopencl as cl

        dt = device_dtype(brick.dtype)
        brick = np.ascontiguousarray(brick, dtype=dt)
        nzb, w, ny, nx = brick.shape
        z0, z1 = crop.start, crop.stop
        nz_out = z1 - z0
        quant = self.quantized and dt == np.uint8
        lut = self.step_lut(spec, positions, quant, value_range)
        lo, hi = value_range
        vmin = np.float32(lo) if hi > lo else np.float32(0.0)
        scale = np.float32(1.0 / (float(hi) - float(lo))) if hi > lo else np.float32(0.0)
        file, kernel_name = KERNELS[spec.mode]
        final = spec.mode != "additive" or spec.normalize == "time"
        defines = {
            "DATA_T": DEVICE_TYPES[dt.name],
            "QUANT": quant,
            "LUT_N": 256 if quant else spec.data_tf.size,
            "ENHANCE": ENHANCE_CODES[spec.enhance.kind],
            "EARLY_EXIT": self.early_exit,
            "IS_MIN": spec.mode == "min",
            "NORM_TIME": spec.mode == "additive" and spec.normalize == "time",
        }
        kern = kernel(self.dc, file, kernel_name, defines)

        ctx, mf = self.dc.context, cl.mem_flags
        host = mf.USE_HOST_PTR if self.host_ptr else mf.COPY_HOST_PTR
        rgba = np.empty((nz_out, ny, nx, 4), dtype=np.float32)
        t_index = np.empty((nz_out, ny, nx), dtype=np.int32) if spec.has_t_index else None
        e = spec.enhance
        args = [
            cl.Buffer(ctx, mf.READ_ONLY | host, hostbuf=brick),
            cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=lut),
            cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.asarray(order, np.int32)),
            cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.asarray(steps, np.int32)),
            np.int32(nx),
            np.int32(ny),
            np.int32(nzb),
            np.int32(w),
            np.int32(z0),
            vmin,
            scale,
            np.array([e.k0, e.k1, e.k2, 0.0], dtype=np.float32),
            np.array([*e.view, 0.0], dtype=np.float32),
        ]
        if spec.mode == "first_hit":
            args.append(np.float32(spec.threshold))
        if spec.mode == "additive":
            norm = reference.additive_norm(spec, positions)
            args.append(np.array([*norm, 0.0], dtype=np.float32))
        outputs = [rgba] + ([t_index] if t_index is not None else [])
        out_flag = (mf.WRITE_ONLY | mf.USE_HOST_PTR) if self.host_ptr else mf.WRITE_ONLY
        out_bufs = [
            cl.Buffer(ctx, out_flag, hostbuf=a)
            if self.host_ptr
            else cl.Buffer(ctx, out_flag, a.nbytes)
            for a in outputs
        ]
        global_size, local_size = self._launch_shape(nx, ny, nz_out)
        queue = self.dc.queue
        with self.dc.lock:
            kern.set_args(*args, *out_bufs)
            cl.enqueue_nd_range_kernel(queue, kern, global_size, local_size)
            for a, buf in zip(outputs, out_bufs, strict=True):
                if self.host_ptr:
                    # Mapping synchronises the host array (a no-op copy on CPU devices).
                    mapped, _ = cl.enqueue_map_buffer(
                        queue, buf, cl.map_flags.READ, 0, a.shape, a.dtype
                    )
                    mapped.base.release(queue)
                else:
                    cl.enqueue_copy(queue, a, buf)
            queue.finish()
        return Partial(rgba, t_index), final

    def _launch_shape(self, nx: int, ny: int, nz: int):
        if self.local_size is not None:
            lx, ly, lz = self.local_size
        else:
            lx, ly, lz = min(64, _round_up(nx, 8)), 1, 1
        return (_round_up(nx, lx), _round_up(ny, ly), _round_up(nz, lz)), (lx, ly, lz)


def _round_up(n: int, m: int) -> int:
    return (n + m - 1) // m * m
