"""The OpenCL integration engine: one z-slab brick in, the slab's chronovolume part out.

Transfer-function work is done once on the host: one data LUT shared by all
steps and a (colour, alpha) factor per step, so a kernel does one interpolated
lookup per voxel-step (quantised uint8 data index their LUT directly); when the
data colour is constant (the default: colour by time) only opacity is looked up; when the
data TF is a few straight pieces (`tf_segments`) they are evaluated instead (the modes that
compare opacity with a threshold look it up where the pieces are too close to decide); and
steps whose 16 voxels all map to zero opacity are skipped (exactly). Bricks are in xytz order
(rows, W, Y, X). On CPU devices buffers wrap the host arrays
(CL_MEM_USE_HOST_PTR) instead of copying; on GPUs (or with host_ptr=False) bricks are copied in
chunks, the upload of one overlapping the kernel of the one before, in the device format asked
for (`chronocl.engine.transfer`).
"""

from __future__ import annotations

import threading
from functools import lru_cache

import numpy as np

from chronocl.core import values
from chronocl.core.memory import aligned_empty, is_aligned
from chronocl.core.tf import lut_lerp32
from chronocl.engine.device import DeviceContext, get_context
from chronocl.engine.program import kernel
from chronocl.engine.transfer import (
    Chunk,
    TransferStats,
    check_format_name,
    chunks_of,
    resolve_format,
    run_chunks,
    stored_dtype,
)
from chronocl.modes.base import KernelInput
from chronocl.modes.spec import IntegrationSpec
from chronocl.reference import Partial

DEVICE_TYPES = {"uint8": "uchar", "uint16": "ushort", "int16": "short", "float32": "float"}
# float16 bricks (device format float16): DATA_T half, loaded with vload_half into float lanes.
HALF_DEFINES = {"DATA_T": "half", "HALF_DATA": True}
ENHANCE_CODES = {"none": 0, "edge": 1, "silhouette": 2}
VEC = 16  # voxels per work-item along x in the vectorised kernels
# Positions in KERNEL_ARGS (kernels/opencl/common.h) of the arguments set per launch.
_ARG_DATA, _ARG_X0, _ARG_NZB, _ARG_ZCROP, _ARG_NZ_OUT = 0, 5, 8, 10, 11


def order_defines(order, w: int) -> dict[str, bool]:
    """ORDER_FORWARD / ORDER_BACKWARD where the integration order is the brick's steps in turn
    or reversed: the kernels then step through the brick without an index table (common.h)."""
    order = np.asarray(order)
    forward = np.array_equal(order, np.arange(w))
    return {
        "ORDER_FORWARD": forward,
        "ORDER_BACKWARD": not forward and np.array_equal(order, np.arange(w)[::-1]),
    }


def device_dtype(dtype: np.dtype) -> np.dtype:
    """The dtype a brick is given to the device in (float64 goes as float32, like the reference)."""
    return stored_dtype(dtype)


def lane_type(dt: np.dtype, lanes: int) -> str:
    """The kernels' DATA_V: the device type with `lanes` lanes (float lanes for float16 data)."""
    base = "float" if dt == np.float16 else DEVICE_TYPES[dt.name]
    return base + (str(lanes) if lanes > 1 else "")


class OpenCLEngine:
    """Integrates xytz bricks on one OpenCL device.

    Each work-item integrates 16 consecutive voxels along x with OpenCL vector types
    (PoCL's implicit vectorisation across work-items is several times slower here);
    the x remainder and gradient enhancement run one voxel per work-item.
    `host_ptr`, `early_exit`, `quantized`, `skip_empty` and `pieces` (the data TF evaluated
    as straight pieces, `tf_segments`) switch the fast paths (default: host pointers on CPU
    devices, the rest on); tests check each against the general path.

    Without host pointers bricks are copied: `device_format` (auto, float32, uint8, uint16,
    float16; `chronocl.engine.transfer`) is what they travel in, `overlap` uploads the next
    chunk of about `chunk_bytes` (None: automatic, 0: the whole brick) while the kernel of
    this one runs, and `last_transfer` holds the timings of the last brick.
    """

    name = "opencl"

    def __init__(
        self,
        device: str | None = None,
        *,
        host_ptr: bool | None = None,
        early_exit: bool = True,
        quantized: bool = True,
        skip_empty: bool = True,
        pieces: bool = True,
        row_blocks: bool = True,
        local_size: tuple[int, int, int] | None = None,
        max_brick_bytes: int | None = None,
        device_format: str = "auto",
        overlap: bool = True,
        chunk_bytes: int | None = None,
    ) -> None:
        self.dc: DeviceContext = get_context(device)
        self.host_ptr = self.dc.is_cpu if host_ptr is None else host_ptr
        self.early_exit = early_exit
        self.quantized = quantized
        self.skip_empty = skip_empty
        self.pieces = pieces
        self.row_blocks = row_blocks
        self.local_size = local_size
        self._max_brick = max_brick_bytes
        self.device_format = check_format_name(device_format)
        self.overlap = overlap
        self.chunk_bytes = chunk_bytes
        self.last_transfer: TransferStats | None = None
        self._luts: dict[tuple, tuple] = {}
        self._luts_lock = threading.Lock()

    def with_options(self, **options) -> OpenCLEngine:
        """A copy of this engine (same device) with some options changed, e.g. device_format."""
        import copy

        if "device_format" in options:
            check_format_name(options["device_format"])
        other = copy.copy(self)
        for key, value in options.items():
            if not hasattr(self, key):
                raise TypeError(f"OpenCLEngine has no option {key!r}")
            setattr(other, key, value)
        other.last_transfer = None
        return other

    @property
    def max_brick_bytes(self) -> int:
        """Largest brick one buffer may hold on this device (or the limit given)."""
        device = min(self.dc.info.max_alloc, self.dc.info.global_mem // 4)
        return int(device if self._max_brick is None else min(device, self._max_brick))

    def luts(
        self,
        spec: IntegrationSpec,
        positions: np.ndarray,
        quant: bool,
        value_range: tuple[float, float],
    ) -> tuple[np.ndarray, np.ndarray, bool, float, np.ndarray | None, int]:
        """The host tables of one integration (`_tables`), kept for the LUT_CACHE most recently
        used: a series integrated slab by slab, or again with the same transfer functions,
        builds them once (about a third of a millisecond each time, where max over 30x128^3
        takes 9)."""
        pos = np.asarray(positions)
        key = (spec, pos.dtype.str, pos.tobytes(), quant, *map(float, value_range), self.pieces)
        with self._luts_lock:  # specs are frozen and hold tuples: hashable
            tables = self._luts.pop(key, None)
            if tables is not None:  # the most recently used go last, the oldest first
                self._luts[key] = tables
        if tables is None:
            tables = self._tables(spec, positions, quant, value_range)
            for a in tables:
                if isinstance(a, np.ndarray):
                    a.setflags(write=False)
            with self._luts_lock:
                while len(self._luts) >= LUT_CACHE:
                    del self._luts[next(iter(self._luts))]
                self._luts[key] = tables
        return tables

    def _tables(
        self,
        spec: IntegrationSpec,
        positions: np.ndarray,
        quant: bool,
        value_range: tuple[float, float],
    ) -> tuple[np.ndarray, np.ndarray, bool, float, np.ndarray | None, int]:
        """The device tables of one integration.

        Returns (data LUT planar (4, N) float32, per-step tc (W, 4) = (rgb_t, a_t), whether
        the data colour is constant (then folded into tc), the skip cut (raw values below it
        look up data opacity 0, or in the threshold modes too little to pass: `skip_bar`), the
        data TF as a few straight pieces (`tf_segments`) or None, and what the pieces' opacity
        is for (SEG_ALPHA: 0 not in the pieces, 1 the opacity itself, 2 a threshold test that
        decides the lanes far from the threshold, the others looked up exactly).
        """
        if quant:  # TF(u(v)) for every byte value, with the kernels' float32 arithmetic
            u = values.normalize(np.arange(256, dtype=np.uint8), *value_range)
            lut = lut_lerp32(spec.data_tf.lut, u).astype(np.float64)
        else:
            lut = spec.data_tf.lut.astype(np.float64)
        rgb_t, a_t = spec.time_tf.evaluate(positions)
        const_color = bool(np.all(lut[:, :3] == lut[:1, :3]))
        colour = rgb_t * lut[0, :3] if const_color else rgb_t
        tc = np.concatenate([colour, a_t[:, None]], axis=1).astype(np.float32)
        segments, seg_alpha = self._segments(lut, const_color, spec, a_t)
        bar = skip_bar(spec, a_t)
        if quant:  # byte values below the first entry above the bar
            live = np.flatnonzero(lut[:, 3] > bar)
            cut = float(min(live[0], 255)) if live.size else 255.0
        else:  # LUT positions x < j only mix entries of intervals below the first live one, j
            live = np.flatnonzero(np.maximum(lut[:-1, 3], lut[1:, 3]) > bar)
            first = int(live[0]) if live.size else len(lut) - 1
            cut = raw_cut(float(first), value_range, len(lut))
        planar = np.ascontiguousarray(lut.T, dtype=np.float32)
        return planar, tc, const_color, cut, segments, seg_alpha

    def _segments(self, lut, const_color: bool, spec: IntegrationSpec, a_t: np.ndarray):
        """The pieces of the data TF the kernels evaluate, and their SEG_ALPHA (see `luts`).

        Opacity joins the pieces where it is straight in as few pieces; a mode comparing it
        with a threshold keeps the LUT's exact opacity and lets its pieces decide only lanes
        farther from the threshold than their error (`opacity_error`, at most
        OPACITY_ERROR_MAX, times a time opacity of at most 1; no gradient enhancement) could
        reach."""
        if not self.pieces:
            return None, 0
        lut32 = lut.astype(np.float32)
        channels = [] if const_color else [0, 1, 2]
        exact = spec.integration.opacity_threshold
        # a threshold test trusts the pieces only where they bound the exact opacity
        if not (exact and (float(a_t.max(initial=0.0)) > 1.0 or spec.enhance.needs_gradient)):
            table = tf_segments(lut32, [*channels, 3])
            if table is not None and (
                not exact or opacity_error(table, len(lut)) <= OPACITY_ERROR_MAX
            ):
                return table, 2 if exact else 1
        return (tf_segments(lut32, channels) if channels else None), 0

    def accumulate(
        self,
        brick: np.ndarray,
        crop: slice,
        steps: np.ndarray | tuple[int, ...],
        positions: np.ndarray,
        order: np.ndarray,
        spec: IntegrationSpec,
        value_range: tuple[float, float],
        out: tuple[np.ndarray, np.ndarray | None] | None = None,
        raw: bool = False,
    ) -> tuple[Partial, bool]:
        """Integrate brick rows `crop` of an xytz brick (rows, W, Y, X).

        `out` = (rgba, t_index) receives the result when given (C-contiguous, float32
        (rows, Y, X, 4) and int32 (rows, Y, X)): a caller that integrates again and again,
        or slab by slab into one volume, avoids allocating and copying.
        Returns the partial result and whether it is final: a mode whose finish is global
        (additive normalised by the volume maximum) or a `raw` call is finished elsewhere.
        """
        import pyopencl as cl

        fmt = resolve_format(self.device_format, brick.dtype, value_range)
        value_range = fmt.device_range  # quantised data: (0, 255) or (0, 65535)
        dt = fmt.dtype
        if self.host_ptr:
            brick = np.ascontiguousarray(brick, dtype=fmt.source)
            if fmt.converts:
                brick = fmt.encode(brick, aligned_empty(brick.shape, dt))
        nzb, w, ny, nx = brick.shape
        z0, z1 = crop.start, crop.stop
        nz_out = z1 - z0
        mode = spec.integration
        quant = self.quantized and dt == np.uint8 and not mode.lut_by_value
        lut, tc, const_color, cut, segments, seg_alpha = self.luts(
            spec, positions, quant, value_range
        )
        vmin, scale = values.normalization(*value_range)
        file, kernel_name = f"{mode.kernel}.cl", mode.kernel_function
        final = not raw and not mode.finalize_is_global(spec)
        given = KernelInput(dt, w, value_range)
        mode_defines, mode_args = mode.kernel_options(spec, positions, raw, given)
        vec = 1 if spec.enhance.needs_gradient else VEC
        defines = {
            "DATA_T": DEVICE_TYPES.get(dt.name),
            "QUANT": quant,
            "LUT_N": lut.shape[1],
            "CONST_COLOR": const_color,
            "TF_SEGS": 0 if segments is None else len(segments[0]),
            "SEG_ALPHA": seg_alpha,
            "ENHANCE": ENHANCE_CODES[spec.enhance.kind],
            "EARLY_EXIT": self.early_exit,
            # a data TF with opacity everywhere leaves nothing to skip: no test per step
            "SKIP_EMPTY": self.skip_empty and cut > (0.0 if quant else float("-inf")),
            "RAW_PARTIAL": raw,
            **order_defines(order, w),
            **mode_defines,
        }
        if dt == np.float16:
            defines.update(HALF_DEFINES)

        ctx, mf = self.dc.context, cl.mem_flags
        rgba, t_index = out if out is not None else (None, None)
        if rgba is None:
            rgba = aligned_empty((nz_out, ny, nx, 4), np.float32)
        if t_index is None and spec.has_t_index:
            t_index = aligned_empty((nz_out, ny, nx), np.int32)
        _check_out(rgba, (nz_out, ny, nx, 4), np.float32)
        if spec.has_t_index:
            _check_out(t_index, (nz_out, ny, nx), np.int32)
        else:
            t_index = None
        e = spec.enhance
        if self.host_ptr:
            aligned = (
                nx % VEC == 0
                and is_aligned(brick)
                and is_aligned(rgba)
                and (t_index is None or is_aligned(t_index))
            )
        else:  # device buffers: aligned to the device's base address alignment (bits)
            aligned = nx % VEC == 0 and self.dc.device.mem_base_addr_align >= 512
        defines["ALIGNED"] = aligned

        def table(a: np.ndarray):
            return cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)

        args = [
            None,  # the brick (or a chunk of it), per launch
            table(lut if segments is None else np.concatenate([lut.ravel(), timed(segments, tc)])),
            table(tc),
            table(np.asarray(order, np.int32)),
            table(np.asarray(steps, np.int32)),
            None,  # x0, per launch
            np.int32(nx),
            np.int32(ny),
            np.int32(nzb),
            np.int32(w),
            np.int32(z0),
            np.int32(nz_out),
            vmin,
            scale,
            np.float32(cut),
            np.array([e.k0, e.k1, e.k2, 0.0], dtype=np.float32),
            np.array([*e.view, 0.0], dtype=np.float32),
        ]
        args += mode_args
        outputs = [rgba] + ([t_index] if t_index is not None else [])

        # Whole vectors of `vec` voxels along x, then the remaining columns one by one.
        n_vec = nx // vec
        launches = [(vec, 0, n_vec)] if n_vec else []
        if n_vec * vec < nx:
            launches.append((1, n_vec * vec, nx - n_vec * vec))
        rows = self._row_blocks(mode, vec, n_vec, ny, nz_out)
        built = []
        for n, x0, count in launches:
            lane_defines = {**defines, "VEC": n, "DATA_V": lane_type(dt, n)}
            if rows and n == VEC:
                # a block of rows keeps a winner's time colours and steps as tables in
                # registers where it has at most TIME_TABLE_MAX steps (PERMUTE_TIME, common.h)
                if spec.has_t_index and w <= TIME_TABLE_MAX:
                    lane_defines["TIME_TABLE"] = True
                state = cl.LocalMemory(rows * count * n * mode.rows_state)
                tail = [np.int32(rows), np.int32(count), state]
                kern = kernel(self.dc, file, mode.rows_kernel, lane_defines)
                built.append((kern, x0, count, tail, -(-ny // rows)))
            else:
                kern = kernel(self.dc, file, kernel_name, lane_defines)
                built.append((kern, x0, count, [], None))

        def launch(queue, data, c: Chunk, out_bufs: list, wait_for: list | None = None) -> list:
            """Enqueue the kernels of brick rows c.r0..c.r1 (output rows c.a..c.b)."""
            args[_ARG_DATA] = data
            args[_ARG_NZB] = np.int32(c.rows)
            args[_ARG_ZCROP] = np.int32(c.zcrop)
            args[_ARG_NZ_OUT] = np.int32(c.b - c.a)
            events = []
            for kern, x0, count, tail, blocks in built:
                args[_ARG_X0] = np.int32(x0)
                kern.set_args(*args, *out_bufs, *tail)
                if blocks is None:
                    global_size, local_size = self._launch_shape(count, ny, c.b - c.a)
                else:  # a work-item per block of rows (in a group of its own: local scratch)
                    global_size, local_size = (blocks, c.b - c.a), (1, 1)
                events.append(
                    cl.enqueue_nd_range_kernel(
                        queue, kern, global_size, local_size, wait_for=wait_for or None
                    )
                )
            return events

        with self.dc.lock:
            if self.host_ptr:
                data = cl.Buffer(ctx, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=brick)
                flags = mf.WRITE_ONLY | mf.USE_HOST_PTR
                out_bufs = [cl.Buffer(ctx, flags, hostbuf=a) for a in outputs]
                launch(self.dc.queue, data, Chunk(z0, z1, 0, nzb), out_bufs)
                self._read_back(outputs, out_bufs)
                self.last_transfer = None
            else:
                row_bytes = w * ny * nx * dt.itemsize
                halo = 1 if spec.enhance.needs_gradient else 0
                chunks = chunks_of(nzb, crop, halo, row_bytes, self.chunk_bytes)
                self.last_transfer = run_chunks(
                    self.dc.streams(), ctx, fmt, brick, chunks, z0, outputs, launch, self.overlap
                )
        return Partial(rgba, t_index), final

    # -- sliding windows: each mode's combine / finish kernels, built with SLIDING ------------
    def combine(self, front: Partial, back: Partial, spec: IntegrationSpec) -> Partial:
        """The partial of `front` then `back` (see the mode's `combine`); new arrays."""
        mode = spec.integration
        file, kernel, defines = mode.combine_kernel(spec)
        shape = front.rgba.shape
        if mode.slides == "invert":  # the aggregated opacity alone
            out = aligned_empty(shape, np.float32)
            self._elementwise(
                mode.kernel, kernel, front.rgba.size, defines, [front.rgba, back.rgba], [out]
            )
            return Partial(out, None)
        rgba = aligned_empty(shape, np.float32)
        t_index = aligned_empty(shape[:-1], np.int32) if mode.has_t_index else None
        value = aligned_empty(shape[:-1], np.float32) if front.value is not None else None
        ins = [a for p in (front, back) for a in (p.rgba, p.t_index, p.value) if a is not None]
        outs = [a for a in (rgba, t_index, value) if a is not None]
        self._elementwise(file, kernel, t_size(shape), defines, ins, outs)
        return Partial(rgba, t_index, value)

    def fixed_add(self, acc: np.ndarray, rgba: np.ndarray, sign: int) -> None:
        """acc (Z, Y, X, C) int64 += sign * fixed-point first C channels of a raw partial."""
        defines = {"CHANNELS": acc.shape[-1]}
        self._elementwise(
            "sums",
            "fixed_add",
            rgba.size // 4,
            defines,
            [rgba],
            [acc],
            [np.int32(sign)],
            inout=True,
        )

    def finish_sums(
        self,
        acc: np.ndarray,
        alpha: np.ndarray | None,
        positions: np.ndarray,
        spec: IntegrationSpec,
    ) -> np.ndarray:
        """The finished RGBA of a window kept as fixed-point sums (see Mode.finish_sums)."""
        mode = spec.integration
        kernel, defines, extra, scalars = mode.finish_kernel(acc, positions, spec)
        out = aligned_empty((*acc.shape[:-1], 4), np.float32)
        ins = [acc, *([alpha] if alpha is not None else []), *extra]
        self._elementwise(mode.kernel, kernel, t_size(out.shape), defines, ins, [out], scalars)
        return out

    def _elementwise(
        self,
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
        """
        import pyopencl as cl

        ctx, mf = self.dc.context, cl.mem_flags
        host = mf.USE_HOST_PTR if self.host_ptr else mf.COPY_HOST_PTR
        ins = [cl.Buffer(ctx, mf.READ_ONLY | host, hostbuf=np.ascontiguousarray(a)) for a in inputs]
        flag = mf.READ_WRITE if inout else mf.WRITE_ONLY
        if self.host_ptr:
            outs = [cl.Buffer(ctx, flag | mf.USE_HOST_PTR, hostbuf=a) for a in outputs]
        elif inout:
            outs = [cl.Buffer(ctx, flag | mf.COPY_HOST_PTR, hostbuf=a) for a in outputs]
        else:
            outs = [cl.Buffer(ctx, flag, a.nbytes) for a in outputs]
        kern = kernel(self.dc, f"{file}.cl", function, {**defines, "SLIDING": True})
        with self.dc.lock:
            kern.set_args(*ins, *outs, *scalars)
            cl.enqueue_nd_range_kernel(self.dc.queue, kern, (n,), None)
            self._read_back(outputs, outs)

    def _read_back(self, outputs: list[np.ndarray], bufs: list) -> None:
        """Make the host arrays hold the kernels' results, then wait (the lock is held)."""
        import pyopencl as cl

        queue = self.dc.queue
        # Enqueued without waiting (the queue runs in order), then one wait for them all:
        # each blocking call cost a round trip through the driver's threads (max 1.3 % faster).
        for a, buf in zip(outputs, bufs, strict=True):
            if self.host_ptr:
                # Mapping synchronises the host array (no copy on CPU devices).
                mapped, _ = cl.enqueue_map_buffer(
                    queue, buf, cl.map_flags.READ, 0, a.shape, a.dtype, is_blocking=False
                )
                mapped.base.release(queue)
            else:
                cl.enqueue_copy(queue, a, buf, is_blocking=False)
        queue.finish()

    def _row_blocks(self, mode, vec: int, n_vec: int, ny: int, nz: int) -> int:
        """Rows a work-item of the mode's rows kernel takes (`Mode.rows_kernel`), 0 where the
        per-vector kernel runs: on GPUs (whose work-items read side by side already), without
        whole vectors along x, or with `row_blocks` off. Each block's state stays within
        ROW_BLOCK_BYTES, and there are blocks enough for every compute unit."""
        if not (self.row_blocks and self.dc.is_cpu and mode.rows_kernel and vec == VEC):
            return 0
        row_bytes = n_vec * VEC * mode.rows_state
        budget = min(ROW_BLOCK_BYTES, self.dc.device.local_mem_size // 2)
        if not n_vec or row_bytes > budget:
            return 0
        rows = min(ny, budget // row_bytes)
        busy = ny * nz // (ROW_BLOCKS_PER_UNIT * self.dc.info.compute_units)
        return max(1, min(rows, busy))

    def _launch_shape(self, count: int, ny: int, nz: int):
        """Global and local size for `count` work-items along x."""
        if self.local_size is not None:
            lx, ly, lz = self.local_size
        elif self.dc.is_cpu:
            lx, ly, lz = min(8, count), min(2, ny), 1
        else:
            lx, ly, lz = min(64, _round_up(count, 32)), 1, 1
        return (_round_up(count, lx), _round_up(ny, ly), _round_up(nz, lz)), (lx, ly, lz)


# A block of rows keeps its state (Mode.rows_state a voxel) in local memory, at most this
# much, so that it stays in a CPU's L2 cache while the steps stream past; blocks per compute
# unit, for an even load.
ROW_BLOCK_BYTES = 64 * 1024
ROW_BLOCKS_PER_UNIT = 4
LUT_CACHE = 16  # integrations whose host tables an engine keeps (OpenCLEngine.luts)
TIME_TABLE_MAX = 32  # steps a rows kernel may look up by register permutes (two 16-lane tables)
MAX_SEGMENTS = 8  # straight pieces of the data TF evaluated without lookups
SEGMENT_TOLERANCE = 2e-7  # how far a LUT entry may lie from its piece (float32 rounding)
# the most `opacity_error` the threshold modes accept: half the kernels' SEG_MARGIN (1e-5)
OPACITY_ERROR_MAX = 5e-6


def tf_segments(lut: np.ndarray, channels: list[int]) -> np.ndarray | None:
    """`channels` of LUT `lut` (N, 4) as at most MAX_SEGMENTS straight pieces, or None.

    Returns (9, S) float32: each piece's first LUT position x0, then the four channels there
    and their slopes per position (channels not asked for are 0); a piece runs to the next
    one's x0. Every entry of the channels asked for lies within SEGMENT_TOLERANCE of its
    piece, so the kernels' sum over the pieces (the value at 0 plus each slope times x's
    run through its piece, kernels/opencl/common.h) equals the LUT's interpolation to float32
    rounding (docs/engine.md). A piece breaks where the second difference of a channel is
    not zero.
    """
    n = len(lut)
    v64 = lut[:, channels].astype(np.float64)
    bend = np.abs(v64[:-2] - 2 * v64[1:-1] + v64[2:]).max(axis=1) > SEGMENT_TOLERANCE
    starts = np.concatenate([[0], np.flatnonzero(bend) + 1])
    if len(starts) > MAX_SEGMENTS:
        return None
    ends = np.concatenate([starts[1:], [n - 1]])
    table = np.zeros((9, len(starts)), dtype=np.float64)
    rows = np.asarray(channels, dtype=int)
    for j, (a, b) in enumerate(zip(starts, ends, strict=True)):
        slope = (v64[b] - v64[a]) / (b - a)
        line = v64[a] + slope * np.arange(b - a + 1)[:, None]
        if np.abs(line - v64[a : b + 1]).max() > SEGMENT_TOLERANCE:
            return None
        table[0, j] = a
        table[1 + rows, j], table[5 + rows, j] = v64[a], slope
    return table.astype(np.float32)


def opacity_error(table: np.ndarray, n: int) -> float:
    """A bound on how far the opacity of pieces `table` (`tf_segments`, LUT of `n` entries)
    evaluated as the kernels do lies from the LUT's interpolation: float32 rounding of each
    product and sum (no partial sum exceeds the value at 0 plus the pieces' changes) and the
    entries' distance from their pieces. The threshold modes trust the pieces beyond 1e-5
    (SEG_MARGIN in kernels/opencl/common.h), so this must stay below OPACITY_ERROR_MAX."""
    x0 = table[0].astype(np.float64)
    length = np.diff(np.append(x0, n - 1))
    swing = abs(float(table[4, 0])) + float(np.sum(np.abs(table[8].astype(np.float64)) * length))
    return 2.0**-24 * (table.shape[1] + 2) * swing + 2 * SEGMENT_TOLERANCE


# How much a step's opacity may exceed its LUT entries times the time opacity: three float32
# roundings of the interpolation and one of the product (about 4.8e-7), with room to spare.
PASS_SLACK = 1.0 + 1e-5


def skip_bar(spec: IntegrationSpec, a_t: np.ndarray) -> float:
    """The data opacity a LUT entry must exceed for a step to matter: 0 (a step whose voxels
    all look up entries of opacity 0 adds nothing), or, in the modes that compare opacity with
    a threshold, the entry below which no step's opacity can exceed the threshold. Opacity is
    the LUT's interpolation, at most its larger entry (to float32 rounding), times the step's
    time opacity; gradient enhancement may raise it, so it keeps the bar at 0."""
    mode = spec.integration
    if not mode.opacity_threshold or spec.enhance.needs_gradient or spec.threshold <= 0:
        return 0.0
    a_max = float(np.max(a_t, initial=0.0))
    return float("inf") if a_max <= 0 else spec.threshold / (a_max * PASS_SLACK)


def timed(segments: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """The kernels' table of `segments` (9, S) for steps of time factors `tc` (W, 4): the
    pieces' x0 (S), then per step and channel the value at 0 and the S slopes, times the
    step's time colour (r, g, b) or opacity (a): (S + W * 4 * (S + 1),) float32."""
    x0, c0, slopes = segments[0], segments[1:5, 0], segments[5:9]
    rows = np.concatenate([c0[:, None], slopes], axis=1).astype(np.float64)  # (4, S + 1)
    per_step = tc.astype(np.float64)[:, :, None] * rows[None]
    return np.concatenate([x0, per_step.ravel()]).astype(np.float32)


def t_size(rgba_shape: tuple) -> int:
    """Voxels of an RGBA array shape (..., 4)."""
    return int(np.prod(rgba_shape[:-1]))


@lru_cache(maxsize=256)  # a bisection of ~34 numpy steps (0.6 ms), asked again on every brick
def raw_cut(position: float, value_range: tuple[float, float], lut_size: int) -> float:
    """The smallest float32 raw value v whose LUT position u(v) * (N - 1) is >= `position`.

    The kernels compute u(v) = clip((v - vmin) * scale, 0, 1) in float32; every step of it
    is monotone, so a binary search over the ordered float32 values finds the exact bound.
    """
    vmin, scale = values.normalization(*value_range)
    n1, target = np.float32(lut_size - 1), np.float32(position)

    def reaches(key: int) -> bool:
        v = _float_of_key(key)
        with np.errstate(over="ignore"):  # near the float32 limits: inf, clipped as on the device
            u = np.clip((v - vmin) * scale, np.float32(0.0), np.float32(1.0))
        return bool(u * n1 >= target)

    if scale == 0:  # a constant field: u = 0 everywhere
        return float("-inf") if np.float32(0.0) >= target else float("inf")
    big = np.finfo(np.float32).max  # data are finite
    low, high = _key_of_float(-big), _key_of_float(big)
    if reaches(low):
        return float("-inf")
    if not reaches(high):
        return float("inf")
    while high - low > 1:  # invariant: not reaches(low), reaches(high)
        mid = (low + high) // 2
        if reaches(mid):
            high = mid
        else:
            low = mid
    return float(_float_of_key(high))


def _key_of_float(v: np.float32) -> int:
    """An integer key that orders float32 values as the numbers they are."""
    bits = int(np.array(v, dtype=np.float32).view(np.int32))
    return bits if bits >= 0 else -(bits & 0x7FFFFFFF)


def _float_of_key(key: int) -> np.float32:
    bits = key if key >= 0 else (-key) | -0x80000000
    return np.array(bits, dtype=np.int32).view(np.float32)[()]


def _check_out(a: np.ndarray, shape: tuple, dtype) -> None:
    if a.shape != shape or a.dtype != dtype or not a.flags.c_contiguous:
        raise ValueError(f"output array must be C-contiguous {np.dtype(dtype)} {shape}")


def _round_up(n: int, m: int) -> int:
    return (n + m - 1) // m * m
