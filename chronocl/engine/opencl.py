"""The OpenCL integration engine: one z-slab brick in, the slab's chronovolume part out.

Buffers, launches and events only: the host tables the kernels look up (data LUT, per-step
time factors, the data TF's straight pieces, the skip cut) come from `chronocl.engine.tables`,
and the kernels' arguments are set by name from their declaration in
`chronocl.engine.kernel_args`. Bricks are in xytz order (rows, W, Y, X). On CPU devices
buffers wrap the host arrays (CL_MEM_USE_HOST_PTR) instead of copying; on GPUs (or with
host_ptr=False) bricks are copied in chunks, the upload of one overlapping the kernel of the
one before (`chronocl.engine.transfer`), in the device format asked for
(`chronocl.engine.device_formats`).
"""

from __future__ import annotations

import numpy as np

from chronocl.core import values
from chronocl.core.memory import aligned_empty, is_aligned, recycled_empty
from chronocl.data.bricks import SlotBrick
from chronocl.engine import elementwise
from chronocl.engine.buffers import DeviceWork, buffer, max_alloc
from chronocl.engine.defines import (
    CPU_PATHS,
    DEVICE_TYPES,
    ENHANCE_CODES,
    HALF_DEFINES,
    VEC,
    lane_type,
    order_defines,
)
from chronocl.engine.device import DeviceContext, get_context
from chronocl.engine.device_formats import check_format_name, resolve_format
from chronocl.engine.device_steps import DeviceBrick, run_resident
from chronocl.engine.gather import on_device
from chronocl.engine.in_place import aligned_part, slot_chunks
from chronocl.engine.kernel_args import INTEGRATE, ROWS
from chronocl.engine.program import kernel
from chronocl.engine.tables import TableCache, Tables
from chronocl.engine.transfer import Chunk, TransferStats, chunks_of, fit, run_chunks
from chronocl.modes.base import KernelInput, Partial
from chronocl.modes.spec import IntegrationSpec


class OpenCLEngine:
    """Integrates xytz bricks on one OpenCL device.

    Each work-item integrates 16 consecutive voxels along x with OpenCL vector types
    (PoCL's implicit vectorisation across work-items is several times slower here);
    the x remainder and gradient enhancement run one voxel per work-item.
    `host_ptr`, `early_exit`, `quantized`, `skip_empty` and `pieces` (the data TF evaluated
    as straight pieces, `tables.tf_segments`) switch the fast paths (default: host pointers on CPU
    devices, the rest on), and `cpu_paths` lowers the x86 paths of the build
    (`chronocl.engine.defines.CPU_PATHS`); tests check each against the general path.

    Without host pointers bricks are copied: `device_format` (auto, float32, uint8, uint16,
    float16; `chronocl.engine.device_formats`) is what they travel in, `overlap` uploads the next
    chunk of about `chunk_bytes` (None: automatic, 0: the whole brick) while the kernel of
    this one runs, and `last_transfer` holds the timings of the last brick.
    """

    name = "opencl"
    writes_display = True  # a uint8 `out` of `accumulate` gets RGBA8 (common.h)
    writes_winners = True  # (u, k) outputs of max and min (common.h: WINNERS)

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
        cpu_paths: str = "native",
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
        if cpu_paths not in CPU_PATHS:
            raise ValueError(f"cpu_paths must be one of {', '.join(CPU_PATHS)}")
        self.cpu_paths = cpu_paths
        self.last_transfer: TransferStats | None = None
        self.last_in_place = False  # whether the last brick was read where its steps lie
        self._luts = TableCache()

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
    def reads_in_place(self) -> bool:
        """Whether the kernels read host memory where it lies (a `SlotBrick` unstacked)."""
        return self.host_ptr

    @property
    def copies_to_device(self) -> bool:
        """Whether bricks travel to the device (a GPU, or a CPU device without host pointers)."""
        return not self.host_ptr

    @property
    def max_brick_bytes(self) -> int:
        """Largest brick one buffer may hold on this device (or the limit given)."""
        device = min(max_alloc(self.dc), self.dc.info.global_mem // 4)
        return int(device if self._max_brick is None else min(device, self._max_brick))

    def luts(
        self,
        spec: IntegrationSpec,
        positions: np.ndarray,
        quant: bool,
        value_range: tuple[float, float],
    ) -> Tables:
        """The host tables of one integration (`chronocl.engine.tables.host_tables`), kept for the
        TUNING.lut_cache most recently used (`TableCache`, shared by `with_options` copies)."""
        return self._luts.get(spec, positions, quant, value_range, self.pieces)

    def accumulate(
        self,
        brick: np.ndarray,
        crop: slice,
        steps: np.ndarray | tuple[int, ...],
        positions: np.ndarray,
        order: np.ndarray,
        spec: IntegrationSpec,
        value_range: tuple[float, float],
        out: tuple[np.ndarray | None, ...] | None = None,
        raw: bool = False,
    ) -> tuple[Partial, bool]:
        """Integrate brick rows `crop` of an xytz brick (rows, W, Y, X): an array, or a
        `SlotBrick` whose steps a CPU device reads where they lie (others stack it).

        `out` = (rgba, t_index) receives the result when given (C-contiguous, float32
        (rows, Y, X, 4) and int32 (rows, Y, X)): a caller that integrates again and again,
        or slab by slab into one volume, avoids allocating and copying. A uint8 `rgba` gets
        the display format (`chronocl.render.upload`'s "f1") of a final result. A mode that
        `writes_winners` takes two more, (u, k): float32 and uint8 (rows, Y, X), each voxel's
        winning u and index into `steps` (a final result of fewer than 255 steps). Device arrays
        (pyopencl's) as `out` of a resident brick are written there, not read back.
        Returns the partial result and whether it is final: a mode whose finish is global
        (additive normalised by the volume maximum) or a `raw` call is finished elsewhere.
        """
        import pyopencl as cl

        fmt = resolve_format(self.device_format, brick.dtype, value_range, spec.mode)
        value_range = fmt.device_range  # quantised data: (0, 255) or (0, 65535)
        dt = fmt.dtype
        resident = isinstance(brick, DeviceBrick)  # steps already on the device
        if resident and (fmt.converts or brick.dtype != fmt.source):
            raise ValueError("steps resident on the device travel in the format they are in")
        slots = resident or isinstance(brick, SlotBrick)
        halo = 1 if spec.enhance.needs_gradient else 0
        if slots and not resident:
            in_place = self.host_ptr and not fmt.converts and brick.dtype == fmt.source
            parts = slot_chunks(brick, crop, halo, self.max_brick_bytes) if in_place else None
            if parts is None:
                brick, slots = np.asarray(brick), False  # stacked: it travels or converts
        self.last_in_place = slots and not resident
        if self.host_ptr and not slots:
            brick = np.ascontiguousarray(brick, dtype=fmt.source)
            if fmt.converts:
                brick = fmt.encode(brick, aligned_empty(brick.shape, dt))
        nzb, w, ny, nx = brick.shape
        z0, z1 = crop.start, crop.stop
        nz_out = z1 - z0
        mode = spec.integration
        quant = self.quantized and dt == np.uint8 and not mode.lut_by_value
        tables = self.luts(spec, positions, quant, value_range)
        segments, cut = tables.segments, tables.cut
        vmin, scale = values.normalization(*value_range)
        file, kernel_name = f"{mode.kernel}.cl", mode.kernel_function
        final = not raw and not mode.finalize_is_global(spec)
        given = KernelInput(dt, w, value_range)
        mode_defines, mode_args = mode.kernel_options(spec, positions, raw, given)
        vec = 1 if spec.enhance.needs_gradient else VEC
        defines = {
            "DATA_T": DEVICE_TYPES.get(dt.name),
            "QUANT": quant,
            "LUT_N": tables.lut.shape[1],
            "CONST_COLOR": tables.const_color,
            "TF_SEGS": 0 if segments is None else len(segments[0]),
            "SEG_ALPHA": tables.seg_alpha,
            "ENHANCE": ENHANCE_CODES[spec.enhance.kind],
            "EARLY_EXIT": self.early_exit,
            # a data TF with opacity everywhere leaves nothing to skip: no test per step
            "SKIP_EMPTY": self.skip_empty and cut > (0.0 if quant else float("-inf")),
            "RAW_PARTIAL": raw,
            "SLOTS": slots,
            "CPU_PATHS": CPU_PATHS[self.cpu_paths],
            **order_defines(order, w),
            **mode_defines,
        }
        if dt == np.float16:
            defines.update(HALF_DEFINES)

        rgba, t_index, *won = out if out is not None else (None, None)
        if won and (not mode.writes_winners or not final or w >= 255):
            raise ValueError(f"{spec.mode} writes no winners here (a final result, W < 255)")
        # a slide's leaves and the like: on the memory of dead ones, already faulted in (fresh,
        # a 256^3 partial's page faults and unmap were 0.1 s of a 0.28 s leaf here)
        if rgba is None:
            rgba = recycled_empty((nz_out, ny, nx, 4), np.float32)
        if t_index is None and spec.has_t_index:
            t_index = recycled_empty((nz_out, ny, nx), np.int32)
        display = defines["RGBA8"] = rgba.dtype == np.uint8  # common.h: final results only
        if display and not final:
            raise ValueError("RGBA8 output takes a final result (not raw, no global finish)")
        _check_out(rgba, (nz_out, ny, nx, 4), np.uint8 if display else np.float32)
        if spec.has_t_index:
            _check_out(t_index, (nz_out, ny, nx), np.int32)
        else:
            t_index = None
        outputs = [rgba] + ([t_index] if t_index is not None else [])
        if won:
            u, k = won
            _check_out(u, (nz_out, ny, nx), np.float32)
            _check_out(k, (nz_out, ny, nx), np.uint8)
            outputs += [u, k]
        defines["WINNERS"] = bool(won)
        unset = [None] * (2 if mode.writes_winners and not won else 0)  # null won_u, won_k
        # every buffer fits the device's largest (`chronocl.engine.buffers`): chunks of rows
        limit = max_alloc(self.dc)
        out_row = max(a[0].nbytes for a in outputs)
        row_bytes = w * ny * nx * dt.itemsize
        whole = [Chunk(z0, z1, 0, nzb)]
        if resident:
            chunks = fit(whole, nzb, halo, 0, out_row, limit)
        elif self.host_ptr:  # slot spans are fitted by slot_chunks; a stacked brick here
            chunks = fit(
                parts if slots else whole, nzb, halo, 0 if slots else row_bytes, out_row, limit
            )
        else:
            chunks = chunks_of(nzb, crop, halo, row_bytes, self.chunk_bytes)
            chunks = fit(chunks, nzb, halo, row_bytes, out_row, limit)
        e = spec.enhance
        if resident:
            aligned = nx % VEC == 0 and brick.zstride % VEC == 0 and not (brick.offsets % VEC).any()
        elif slots:
            aligned = (
                nx % VEC == 0
                and brick.zstride % VEC == 0
                and all(aligned_part(brick.rows(c.r0, c.r1), VEC) for c in chunks)
                and is_aligned(rgba)
                and (t_index is None or is_aligned(t_index))
            )
        elif self.host_ptr:
            aligned = (
                nx % VEC == 0
                and all(is_aligned(brick[c.r0]) for c in chunks)
                and is_aligned(rgba)
                and (t_index is None or is_aligned(t_index))
            )
        else:  # device buffers: aligned to the device's base address alignment (bits)
            aligned = nx % VEC == 0 and self.dc.device.mem_base_addr_align >= 512
        defines["ALIGNED"] = aligned

        def table(a: np.ndarray):
            return buffer(self.dc, a)  # a copy: the host array may go

        args = INTEGRATE.bind(
            data=None,  # the brick (or a chunk of it), per launch
            lut=table(tables.lut_buffer()),
            tc=table(tables.tc),
            order=table(np.asarray(order, np.int32)),
            steps=table(np.asarray(steps, np.int32)),
            step_base=None,  # per launch
            zstride=brick.zstride if slots else 0,
            x0=None,  # per launch
            nx=nx,
            ny=ny,
            nzb=nzb,
            w=w,
            zcrop=z0,
            nz_out=nz_out,
            vmin=vmin,
            scale=scale,
            cut=cut,
            enh=[e.k0, e.k1, e.k2, 0.0],
            view=[*e.view, 0.0],
        )
        extras = list(mode_args.values())  # the mode's own, by name (tests/test_kernel_args.py)

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
                tail = ROWS.bind(rows=rows, nvec=count, st=state).values
                kern = kernel(self.dc, file, mode.rows_kernel, lane_defines)
                built.append((kern, x0, count, tail, -(-ny // rows)))
            else:
                kern = kernel(self.dc, file, kernel_name, lane_defines)
                built.append((kern, x0, count, [], None))

        step_base = table(np.zeros(1, np.int64))  # stacked bricks: unused

        def launch(queue, data, c: Chunk, out_bufs: list, wait_for: list | None = None) -> list:
            """Enqueue the kernels of brick rows c.r0..c.r1 (output rows c.a..c.b)."""
            args.set(data=data, step_base=step_base, nzb=c.rows, zcrop=c.zcrop, nz_out=c.b - c.a)
            events = []
            for kern, x0, count, tail, blocks in built:
                args.set(x0=x0)
                kern.set_args(*args.values, *extras, *out_bufs, *unset, *tail)
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

        with DeviceWork(self.dc) as work:
            if resident:
                for c in chunks:
                    step_base = work.buffer(brick.offsets + c.r0 * brick.zstride)
                    run_resident(work, brick, outputs, launch, c, z0)
                self.last_transfer = None
            elif self.host_ptr:
                # A stacked brick is one chunk where it fits; steps read in place, a chunk of
                # rows per buffer where they span more than one holds.
                for c in chunks:
                    part = brick.rows(c.r0, c.r1) if slots else None
                    host = brick[c.r0 : c.r1] if part is None else part.block
                    data = work.buffer(host, in_place=True)
                    if part is not None:
                        step_base = work.buffer(part.offsets)
                    rows = [a[c.a - z0 : c.b - z0] for a in outputs]
                    bufs = [work.buffer(a, access="w", in_place=True) for a in rows]
                    launch(self.dc.queue, data, c, bufs)
                    for a, buf in zip(rows, bufs, strict=True):
                        work.read(a, buf, in_place=True)
                self.last_transfer = None
            else:
                streams = self.dc.streams()
                work.queues += [streams.upload, streams.compute, streams.download]
                self.last_transfer = run_chunks(
                    streams, self.dc, fmt, brick, chunks, z0, outputs, launch, self.overlap
                )
        return Partial(rgba, t_index), final

    # -- sliding windows: each mode's combine / finish kernels (`chronocl.engine.elementwise`)
    def combine(
        self, front: Partial, back: Partial, spec: IntegrationSpec, rgba8: bool = False
    ) -> Partial:
        """The partial of `front` then `back` (see the mode's `combine`); new arrays (with
        `rgba8`, its colour in the display format: `elementwise.combine`)."""
        return elementwise.combine(self.dc, self.host_ptr, front, back, spec, rgba8)

    def fixed_add(self, acc: np.ndarray, rgba: np.ndarray, sign: int) -> None:
        """acc (Z, Y, X, C) int64 += sign * fixed-point first C channels of a raw partial."""
        elementwise.fixed_add(self.dc, self.host_ptr, acc, rgba, sign)

    def finish_sums(
        self,
        acc: np.ndarray,
        alpha: np.ndarray | None,
        positions: np.ndarray,
        spec: IntegrationSpec,
    ) -> np.ndarray:
        """The finished RGBA of a window kept as fixed-point sums (see Mode.finish_sums)."""
        return elementwise.finish_sums(self.dc, self.host_ptr, acc, alpha, positions, spec)

    def gather(self, t_index, arrays, steps, value_range, change: bool):
        """Each voxel's winner read from its winning step alone on the device (`on_device`)."""
        return on_device(self.dc, t_index, arrays, steps, value_range, change)

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
            lx, ly, lz = 8, 2, 1  # whatever the shape: PoCL compiles once per group size
        else:
            lx, ly, lz = min(64, _round_up(count, 32)), 1, 1
        return (_round_up(count, lx), _round_up(ny, ly), _round_up(nz, lz)), (lx, ly, lz)


# A block of rows keeps its state (Mode.rows_state a voxel) in local memory, at most this much,
# so that it stays in L2 while the steps stream past; blocks per compute unit, for an even load.
ROW_BLOCK_BYTES = 64 * 1024
ROW_BLOCKS_PER_UNIT = 4
TIME_TABLE_MAX = 32  # steps a rows kernel may look up by register permutes (two 16-lane tables)


def _check_out(a: np.ndarray, shape: tuple, dtype) -> None:
    if a.shape != shape or a.dtype != dtype or not a.flags.c_contiguous:
        raise ValueError(f"output array must be C-contiguous {np.dtype(dtype)} {shape}")


def _round_up(n: int, m: int) -> int:
    return (n + m - 1) // m * m
