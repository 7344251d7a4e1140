"""Recolouring brick by brick on the OpenCL device of the host, into RGBA8 (llvmpipe's way).

Most of a volume is empty under the usual TFs (the vortex: 10-16 % of its 8^3 bricks hold any
opacity), and a voxel's opacity is exactly 0 where the data TF's opacity is 0 at both LUT
entries around its value u* or the time TF's opacity is 0 at its step k*. So `prepare` gives
each brick of the empty-space grid (chronocl/render/brick_grid.py's 8^3) a summary of its
winners: the smallest and largest u* and a bit per step k* present (bit 63: step 63 or later).
Per edit a brick may be coloured only where the data TF has opacity on a LUT segment of
[min, max] and the time TF on a step present (sufficient: the others are 0 for sure, as the
kernel computes them).

`apply` then runs kernels/opencl/recolour_bricks.cl over the bricks that may be coloured now
or were in the array it writes into (its one output, written over at every edit: the viewer
draws its frames from the texture and reads the array for probes and saves on the thread that
recolours, so it changes only between frames), and reads back the occupied voxels' box and the
brick grid (grown by one voxel, as brick_grid.py defines it) over the bricks next to a
coloured one: both are then exactly what the viewer's upload finds in the whole array.
`recolour.show` writes only the bricks that may differ from what the texture holds. The
winners and the output are used in place on a CPU device (host pointers, nothing copied).

The device holds the winners in z-spans of whole rows of bricks, each span's u, k and output
a buffer of its own under the device's largest (`chronocl.engine.buffers.max_alloc`; one span
where the volume fits: at 1024^3 u alone is 4 GB, over PoCL's 2-4 GB on a CPU). Each kernel
runs per span on the span as a volume of its own: a brick's summary, colours, peaks and box
read only its own voxels, so the summaries and colours are the whole volume's, the box is
moved by the span's first z, and the grid grows the peaks of every span's bricks together
(`grown_grid`): a brick's neighbours across a span boundary lend their faces as within one.
"""

from __future__ import annotations

import itertools
import math
import threading

import numpy as np

from chronocl.core.memory import ALIGN, aligned_empty, is_aligned, recycled_empty
from chronocl.engine.gather import aligned, index_type, on_device
from chronocl.integration.interactive.winners import Winners, step_table
from chronocl.modes.spec import IntegrationSpec
from chronocl.render import brick_grid
from chronocl.render.recolour import Changed, empty_bounds
from chronocl.render.volume import Volume

B = brick_grid.BRICK
RUN_BRICKS = 64  # bricks a work-item recolours at most (a 512-voxel row)
STEP_BITS = 64  # bits of a brick's step mask; the last stands for every step from 63 on
RECOLOUR_H = "recolour.h"  # a winner's colour and its RGBA8, prepended to recolour_bricks.cl


def bricks_defines(k_dtype) -> dict[str, object]:
    """The -D options of kernels/opencl/recolour_bricks.cl (summaries, recolour, peaks)."""
    return {"K_T": index_type(k_dtype), "BRICK": B}


def shown_output(rgba, shape: tuple) -> bool:
    """Whether `rgba`, the RGBA the window shows (integrated or recoloured under the winners'
    spec), can be a recolouring's output for winners of `shape` (Z, Y, X): RGBA8 of that
    shape where PoCL writes in place. The viewer's display integration writes RGBA8 (slides
    and small volumes give float32): its first TF edit then recolours into the memory the
    frame holds, instead of a second array (at 512^3, 512 MB a view, whose zeroing took
    0.5 s of that edit)."""
    return (
        isinstance(rgba, np.ndarray)
        and rgba.dtype == np.uint8
        and rgba.shape == (*shape, 4)
        and rgba.flags.c_contiguous
        and rgba.flags.writeable
        and is_aligned(rgba)
    )


class Span:
    """One z-span of whole rows of bricks: rows [g0, g1) of the grid, voxels z [z0, z1), its
    winners' u and k on the device (reading the host's in place on a CPU)."""

    def __init__(self, g0: int, g1: int, z0: int, z1: int, u, k) -> None:
        self.g0, self.g1, self.z0, self.z1, self.u, self.k = g0, g1, z0, z1, u, k

    def release(self) -> None:
        self.u.release()
        self.k.release()


def span_rows(shape: tuple, limit: int) -> list[tuple[int, int]]:
    """Rows of bricks [g0, g1) of each span of winners of `shape` (Z, Y, X): u (4 bytes a
    voxel, the largest of u, k and the RGBA8 output) of a span under `limit` bytes, cut where
    the spans' k (1 byte a voxel) start 64-byte aligned where that leaves a row of bricks a
    span (PoCL then uses the host's memory in place). One span where the whole fits; raises
    DeviceLimitError where one row of bricks does not."""
    from chronocl.engine.buffers import DeviceLimitError

    nz, ny, nx = shape
    gz = brick_grid.grid_shape(tuple(shape))[0]
    if nz * ny * nx * 4 <= limit:
        return [(0, gz)]
    row = B * ny * nx  # voxels of a full row of bricks
    rows = limit // (row * 4)
    if rows < 1:
        raise DeviceLimitError(
            f"a row of {B} z planes of the winners ({row * 4} bytes of u) is over the OpenCL "
            f"device's largest buffer ({limit} bytes)"
        )
    aligned_rows = ALIGN // math.gcd(row, ALIGN)
    if rows >= aligned_rows:
        rows -= rows % aligned_rows
    return [(g, min(gz, g + rows)) for g in range(0, gz, rows)]


class BrickWinners:
    """A window's winners on the OpenCL device, in z-spans of rows of bricks (`Span`), with
    their brick summaries, and the one RGBA8 output they are recoloured into, with the bricks
    that may be coloured in it."""

    def __init__(self, w: Winners, spans: list[Span], arrays: tuple) -> None:
        """`spans`: u and k on the device, reading `arrays` (u and k) in place on a CPU."""
        self.w, self.spans, self.arrays = w, spans, arrays
        nz, ny, nx = w.u.shape
        self.dims = (nx, ny, nz)
        self.grid = brick_grid.grid_shape((nz, ny, nx))
        n = int(np.prod(self.grid))
        self.umin, self.umax = np.empty(n, np.float32), np.empty(n, np.float32)
        self.steps = np.empty(n, np.uint64)  # the summaries, written by `prepare`
        # the RGBA8 output and its bricks that may be coloured (None: taken by `take_held`)
        self.output: tuple[np.ndarray, np.ndarray] | None = None

    def take_output(self, held: tuple | None, start) -> None:
        """Write into `start` where it is the RGBA8 the window shows (`shown_output`): the
        first edit rewrites its bricks the winners' spec may colour; else into `held`, the last
        window's output (`take_held`: it says which bricks hold colour, so nothing is zeroed);
        else into one from the pool of reused host buffers, zeroed here, so that no edit pays
        for first touching its pages (512^3: 0.5 s)."""
        shape = self.w.u.shape
        if shown_output(start, shape):
            self.output = (start, self.coloured(self.w.spec))
        elif takes_over(held, shape):
            self.output = held
        else:
            self.output = (aligned_zeros((*shape, 4)), np.zeros(self.grid, bool))

    def shape_args(self, span: Span) -> list:
        """The kernels' volume: the span's z planes, as a volume of their own."""
        _, gy, gx = self.grid
        nx, ny, _ = self.dims
        return [np.int32(v) for v in (nx, ny, span.z1 - span.z0, gx, gy)]

    def bricks_of(self, span: Span) -> tuple[int, int]:
        """The grid's flat brick indices [a, b) of `span`."""
        _, gy, gx = self.grid
        return span.g0 * gy * gx, span.g1 * gy * gx

    def coloured(self, spec: IntegrationSpec) -> np.ndarray:
        """(Z, Y, X)/B bool: the bricks whose voxels may have opacity > 0 under `spec`."""
        lut = np.asarray(spec.data_tf.lut, dtype=np.float32)
        table = step_table(spec, self.w.steps, self.w.n_steps)
        n = lut.shape[0]
        # segment i (entries i, i + 1) colours a value whose i0 is i, if either has opacity
        segment = (lut[:-1, 3] != 0) | (lut[1:, 3] != 0)
        prefix = np.concatenate([[0], np.cumsum(segment)])
        held = self.umax >= self.umin  # a brick with any winner
        scale = np.float32(n - 1)
        lo = np.nan_to_num(self.umin * scale, posinf=0, neginf=0).astype(np.int64) - 1
        hi = np.nan_to_num(self.umax * scale, posinf=0, neginf=0).astype(np.int64) + 1
        lo, hi = np.clip(lo, 0, n - 2), np.clip(hi, 0, n - 2)  # a segment of margin each side
        data = prefix[hi + 1] > prefix[lo]
        alpha = table[:, 3] != 0
        bits = np.uint64(0)
        for k in np.flatnonzero(alpha[: STEP_BITS - 1]):
            bits |= np.uint64(1) << np.uint64(k)
        if alpha[STEP_BITS - 1 :].any():
            bits |= np.uint64(1) << np.uint64(STEP_BITS - 1)
        steps = (self.steps & bits) != 0
        return (held & data & steps).reshape(self.grid)

    def take_held(self) -> tuple | None:
        """The output, for the next winners of the same shape (`BrickRecolourer.prepare`'s
        `held`); these recolour no more."""
        held, self.output = self.output, None
        return held

    def release(self) -> None:
        for span in self.spans:
            span.release()
        self.spans = []
        self.output = None


class BrickRecolourer:
    """`chronocl.render.recolour.Recolourer` on the OpenCL device `device` (RGBA8 out)."""

    gl_thread = False  # its RGBA8 goes up in `recolour.show`

    def __init__(self, device: str | None = None) -> None:
        from chronocl.engine.device import get_context

        self.dc = get_context(device)

    def _program(self, k_dtype):
        from chronocl.engine.program import build

        return build(self.dc, "recolour_bricks.cl", bricks_defines(k_dtype), common=RECOLOUR_H)

    def prepare(self, winners: Winners, held: tuple | None = None, start=None) -> BrickWinners:
        """The winners on the device in z-spans of rows of bricks, each span's buffers under
        its largest (`span_rows`), each brick summarised, with their output
        (`BrickWinners.take_output`). Raises DeviceLimitError only where one row of bricks is
        over the device's largest buffer."""
        import pyopencl as cl

        from chronocl.engine.buffers import DeviceWork, buffer, max_alloc

        w, dc = winners, self.dc
        rows = span_rows(w.u.shape, max_alloc(dc))
        arrays = (aligned(w.u), aligned(w.k))
        nz = w.u.shape[0]
        spans: list[Span] = []
        try:
            for g0, g1 in rows:
                z0, z1 = g0 * B, min(nz, g1 * B)
                u = buffer(dc, arrays[0][z0:z1], in_place=dc.is_cpu)
                try:
                    k = buffer(dc, arrays[1][z0:z1], in_place=dc.is_cpu)
                except BaseException:
                    u.release()
                    raise
                spans.append(Span(g0, g1, z0, z1, u, k))
        except BaseException:
            for span in spans:
                span.release()
            raise
        prepared = BrickWinners(w, spans, arrays)
        try:
            program = self._program(w.k.dtype)
            for span in spans:
                lo, hi = prepared.bricks_of(span)
                summary = (prepared.umin[lo:hi], prepared.umax[lo:hi], prepared.steps[lo:hi])
                with DeviceWork(dc) as work:
                    outs = [work.buffer(a, access="w") for a in summary]
                    kern = cl.Kernel(program, "summarise")
                    kern.set_args(
                        span.u, span.k, np.uint32(w.none), *prepared.shape_args(span), *outs
                    )  # fmt: skip
                    cl.enqueue_nd_range_kernel(dc.queue, kern, (hi - lo,), None)
                    for a, buf in zip(summary, outs, strict=True):
                        work.read(a, buf, in_place=False)
        except BaseException:
            prepared.release()
            raise
        prepared.take_output(held, start)
        return prepared

    def apply(
        self, prepared: BrickWinners, spec: IntegrationSpec, into: Volume | None = None
    ) -> Changed:
        """Premultiplied RGBA8 (Z, Y, X, 4) of the winners under `spec`, written over their
        one output in the bricks coloured now or in it, with the grid and occupied box of the
        result; to be shown in `into` (`recolour.show`)."""
        p, w = prepared, prepared.w
        coloured = p.coloured(spec)
        out, before = p.output
        # until the kernel has run, any brick of either may hold colour (a failure part way
        # leaves some of each): the next edit rewrites them all
        p.output = (out, coloured | before)
        todo = np.flatnonzero(coloured | before).astype(np.int32)
        peaks = np.zeros((max(len(todo), 1), 27), np.uint8)
        box = np.zeros((max(len(todo), 1), 6), np.int32)
        lut = np.ascontiguousarray(spec.data_tf.lut, dtype=np.float32)
        table = step_table(spec, w.steps, w.n_steps)
        program = self._program(w.k.dtype) if len(todo) else None
        for span in p.spans:
            lo, hi = p.bricks_of(span)
            at = np.searchsorted(todo, [lo, hi])
            if at[0] == at[1]:
                continue  # none of its bricks coloured, now or before
            self._recolour_span(
                p, span, program, lut, table, todo[at[0] : at[1]] - lo,
                peaks[at[0] : at[1]], box[at[0] : at[1]],
            )  # fmt: skip
            box[at[0] : at[1], 2::3][box[at[0] : at[1], 3] >= 0] += span.z0  # the span's z
        # bricks not rewritten hold nothing: not coloured now, nor in the array before
        stats = np.zeros((*p.grid, 27), np.uint8)
        stats.reshape(-1, 27)[todo] = peaks[: len(todo)]
        bounds = empty_bounds()
        filled = box[: len(todo), 3] >= 0
        if len(todo) and filled.any():
            bounds[:3] = box[: len(todo)][filled, :3].min(axis=0)
            bounds[3:] = box[: len(todo)][filled, 3:].max(axis=0)
        p.output = (out, coloured)
        return Changed(into, bounds, grown_grid(stats), out, coloured, len(todo))

    def _recolour_span(self, p: BrickWinners, span: Span, program, lut, table, todo, peaks, box):
        """Recolour the bricks `todo` of `span` (some; indices in the span's grid) into its z
        planes of the output, their peaks and box (z in the span) into `peaks` and `box`."""
        import pyopencl as cl

        from chronocl.engine.buffers import DeviceWork

        out = p.output[0][span.z0 : span.z1]
        cpu, w = self.dc.is_cpu, p.w
        with DeviceWork(self.dc) as work:
            out_buf = work.buffer(out, access="rw", in_place=cpu)
            kern = cl.Kernel(program, "recolour")
            runs = _runs(todo, p.grid[2])
            ins = [work.buffer(a) for a in (lut, table, todo, runs)]
            outs = [work.buffer(a, access="w") for a in (peaks, box)]
            kern.set_args(
                span.u, span.k, ins[0], np.int32(lut.shape[0]), ins[1], np.uint32(w.none),
                out_buf, *ins[2:], *p.shape_args(span), *outs,
            )  # fmt: skip
            cl.enqueue_nd_range_kernel(self.dc.queue, kern, (len(runs) - 1,), None)
            work.read(peaks, outs[0], in_place=False)
            work.read(box, outs[1], in_place=False)
            work.read(out, out_buf, cpu)  # on a CPU the host pointer holds it, mapped


def aligned_zeros(shape) -> np.ndarray:
    """Zeroed uint8 of `shape`, 64-byte aligned (PoCL writes it in place), its pages touched:
    on the memory of a dead output of its size where there is one (`recycled_empty`; a
    frame's RGBA8 or t_index), which goes back to the pool when the winners are released."""
    out = recycled_empty(tuple(shape), np.uint8)
    out[...] = 0
    return out


def grown_grid(stats: np.ndarray) -> np.ndarray:
    """The brick grid (brick_grid.py: the largest opacity of each brick grown by one voxel)
    from per brick (Z, Y, X, 27) the largest opacity of its parts [cz][cy][cx] (per axis 0:
    the low face, 1: all, 2: the high face): the neighbour at offset d lends the part facing
    the brick (its high face where d < 0, all where d = 0, its low face where d > 0)."""
    parts = stats.reshape(*stats.shape[:3], 3, 3, 3)
    grid = parts[..., 1, 1, 1].copy()
    gz, gy, gx = grid.shape
    for d in itertools.product((-1, 0, 1), repeat=3):
        if d == (0, 0, 0):
            continue
        dz, dy, dx = (1 - s for s in d)  # the class lent: 2 for -1, 1 for 0, 0 for +1
        lent = parts[..., dz, dy, dx]
        sizes = zip(d, (gz, gy, gx), strict=True)
        src, dst = zip(*[(_part(s, n), _part(-s, n)) for s, n in sizes], strict=True)
        np.maximum(grid[dst], lent[src], out=grid[dst])
    return grid


def _runs(todo: np.ndarray, gx: int) -> np.ndarray:
    """Where the runs of `todo` (ascending brick indices, x fastest) start, and its length:
    bricks consecutive along x in one row of bricks, at most RUN_BRICKS a run."""
    n = len(todo)
    start = np.ones(n, bool)
    start[1:] = (todo[1:] != todo[:-1] + 1) | (todo[1:] % gx == 0)
    first = np.flatnonzero(start)
    at = np.arange(n) - first[np.cumsum(start) - 1]  # place in its run
    start |= at % RUN_BRICKS == 0
    return np.append(np.flatnonzero(start), n).astype(np.int32)


def _part(shift: int, n: int) -> slice:
    """The indices i of an axis of n whose i - shift is inside it too."""
    return slice(max(shift, 0), n + min(shift, 0))


def takes_over(held: tuple | None, shape: tuple) -> bool:
    """Whether winners of `shape` (Z, Y, X) prepared with `held`, the output of the last ones
    (`BrickWinners.take_held`), write into it instead of an array of their own."""
    if held is None:
        return False
    rgba, coloured = held
    return rgba.shape == (*shape, 4) and coloured.shape == brick_grid.grid_shape(tuple(shape))


_warmed: set = set()
_warm_lock = threading.Lock()


def warm_kernels(dtype, device: str | None) -> None:
    """Run the OpenCL kernels of a first TF edit in max, min, first_hit and change (the
    gathers, the brick summaries, the brick recolour) once per process, device and data type,
    on a window of two steps of one brick: PoCL loads a kernel's code at its first run, about
    40 ms a kernel here, which was 0.27 s of the first edit after a mode switch at 512^3. The
    viewer calls it beside its first frame (`chronocl.viewer.worker`)."""
    key = (device, np.dtype(dtype).name)
    with _warm_lock:  # one at a time: a second caller finds them warm
        if key in _warmed:
            return
        _warm(dtype, device)
        _warmed.add(key)


def _warm(dtype, device: str | None) -> None:
    from chronocl.engine.device import get_context
    from chronocl.integration.inmemory import make_spec

    block = aligned_empty((2, B, B, B), dtype)
    block[...] = 0
    t_index = aligned_empty((B, B, B), np.int32)
    t_index[...] = 1
    arrays, steps, vr = {0: block[0], 1: block[1]}, (0, 1), (0.0, 1.0)
    for mode in ("max", "change"):  # change's gather is a kernel of its own
        spec = make_spec(mode)
        u, k = on_device(get_context(device), t_index, arrays, steps, vr, mode == "change")
        w = Winners(u, k, steps, 2, vr, spec)
        recolourer = BrickRecolourer(device)
        prepared = recolourer.prepare(w)
        try:
            recolourer.apply(prepared, spec)
        finally:
            prepared.release()
