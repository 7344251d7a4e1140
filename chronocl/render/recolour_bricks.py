"""Recolouring brick by brick on the OpenCL device, and writing only what changed (llvmpipe).

A TF edit in max, min, first_hit or change mode recolours the window's winners (value u* and
step k* per voxel, `chronocl.integration.interactive.winners.Winners`). Most of a volume is
empty under the usual TFs (the vortex: 10-16 % of its 8^3 bricks hold any opacity), and a
voxel's opacity is exactly 0 where the data TF's opacity is 0 at both LUT entries around u*
or the time TF's opacity is 0 at k*. So, once per window, each brick of the empty-space grid
(chronocl/render/brick_grid.py's 8^3) gets a summary of its winners: the smallest and largest
u* and a bit per step k* present (bit 63: step 63 or later). Per edit a brick may be coloured
only where the data TF has opacity on a LUT segment of [min, max] and the time TF on a step
present (a sufficient test: the others are 0 for sure, as the kernel computes them).

The recolour kernel then runs over the bricks that may be coloured now or were in the array
it writes into (its one output, written over at every edit: the viewer draws its frames from
the texture and reads the array for probes and saves on the thread that recolours, so it
changes only between frames), in the arithmetic of the full pass (kernels/opencl/recolour.cl,
RGBA8 rounded to nearest even), and a second kernel reads back the occupied voxels' box and
the brick grid (grown by one voxel, as brick_grid.py defines it) over the bricks next to a
coloured one: both are then exactly what the viewer's upload finds in the whole array. The
texture is written only over the bricks that may differ from what it holds (coloured before
or now), a box of them per z-slab of bricks, straight from the array (GL's unpack row
length: no copy).
"""

from __future__ import annotations

import itertools
import threading
from dataclasses import dataclass

import numpy as np

from chronocl.core.memory import aligned_empty
from chronocl.integration.interactive.winners import Winners, step_table
from chronocl.modes.spec import IntegrationSpec
from chronocl.render import brick_grid
from chronocl.render.recolour_host import (
    RECOLOUR_H,
    HostRecolour,
    gather,
    index_type,
    shown_output,
)

B = brick_grid.BRICK
RUN_BRICKS = 64  # bricks a work-item recolours at most (a 512-voxel row)
STEP_BITS = 64  # bits of a brick's step mask; the last stands for every step from 63 on


def bricks_defines(k_dtype) -> dict[str, object]:
    """The -D options of kernels/opencl/recolour_bricks.cl (summaries, recolour, peaks)."""
    return {"K_T": index_type(k_dtype), "BRICK": B}


@dataclass
class Sparse:
    """One brick-wise recolour: the RGBA8 array (Z, Y, X, 4), the bricks that may be coloured
    (`coloured`, (Z, Y, X)/B bool), those rewritten, the brick grid and the occupied box."""

    rgba: np.ndarray
    coloured: np.ndarray
    rewritten: int  # bricks recoloured
    bricks: np.ndarray  # uint8 grid, as brick_grid.from_rgba(rgba) gives it
    bounds: np.ndarray  # int32 (lo x, y, z, hi x, y, z) of voxels with opacity > 0; hi -1: none


class BrickRecolour(HostRecolour):
    """A window's winners on the OpenCL device with their brick summaries, recoloured into
    RGBA8 brick by brick (`sparse`); `recolour` (the whole volume, any format) as before."""

    def __init__(
        self, w: Winners, device: str | None = None, held: list | None = None, start=None
    ) -> None:
        """`held`: the last window's output (`take_held`); `start`: the RGBA8 the window shows
        (`shown_output`), taken first: its bricks that `w.spec` may colour are rewritten by
        the first edit as those of an output coloured under it."""
        import pyopencl as cl

        from chronocl.engine.buffers import DeviceLimitError, DeviceWork, buffer, max_alloc

        super().__init__(w, device)
        self._own: list = []  # whole-volume u and k, where the spans are several
        # its kernels index the whole volume: u (4 bytes a voxel) and the RGBA8 output each in
        # one buffer, or none (the spans above are cut for float32 RGBA, 16 bytes a voxel)
        if w.u.size * 4 > max_alloc(self.dc):
            self.release()
            raise DeviceLimitError("the winners are over the device's largest buffer")
        if len(self.parts) == 1:
            _, _, self.u, self.k = self.parts[0]
        else:
            cpu = self.dc.is_cpu
            self.u = buffer(self.dc, self._u, in_place=cpu)
            self.k = buffer(self.dc, self._k, in_place=cpu)
            self._own = [self.u, self.k]
        nz, ny, nx = w.u.shape
        self.dims = (nx, ny, nz)
        self.grid = brick_grid.grid_shape((nz, ny, nx))
        n = int(np.prod(self.grid))
        self.umin, self.umax = np.empty(n, np.float32), np.empty(n, np.float32)
        self.steps = np.empty(n, np.uint64)
        program = self._program()
        with DeviceWork(self.dc) as work:
            outs = [work.buffer(a, access="w") for a in self._summary()]
            kern = cl.Kernel(program, "summarise")
            kern.set_args(
                self.u, self.k, np.uint32(w.none), *self._shape_args(), *outs
            )  # fmt: skip
            cl.enqueue_nd_range_kernel(self.dc.queue, kern, (n,), None)
            for a, buf in zip(self._summary(), outs, strict=True):
                work.read(a, buf, in_place=False)
        # the output array, with the bricks that may be coloured in it: the shown RGBA8,
        # coloured under the winners' spec (its other bricks hold nothing); else the output of
        # the winners prepared before (`held`, a slot's last window: any shape alike); else
        # one zeroed here, so that no edit pays for first touching its pages (512^3: 0.5 s)
        if shown_output(start, w.u.shape):
            self._held = [(start, self.coloured(w.spec))]
        elif takes_over(held, w.u.shape):
            self._held = list(held)
        else:
            self._held = [(aligned_zeros((*w.u.shape, 4)), np.zeros(self.grid, bool))]

    def _summary(self) -> tuple[np.ndarray, ...]:
        return self.umin, self.umax, self.steps

    def _shape_args(self) -> list:
        _, gy, gx = self.grid
        return [np.int32(v) for v in (*self.dims, gx, gy)]

    def _program(self):
        from chronocl.engine.program import build

        return build(
            self.dc, "recolour_bricks.cl", bricks_defines(self._k.dtype), common=RECOLOUR_H
        )

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

    def sparse(self, spec: IntegrationSpec) -> Sparse:
        """Premultiplied RGBA8 (Z, Y, X, 4) of the winners under `spec`, written over the last
        one (its one output array: `HostRecolour.recolour`'s `reuse`) in the bricks coloured
        now or in it; with the grid and occupied box of the result."""
        import pyopencl as cl

        from chronocl.engine.buffers import DeviceWork

        w = self.w
        coloured = self.coloured(spec)
        out, before = self._held[0]
        redo = (coloured | before).ravel()
        # until the kernel has run, any brick of either may hold colour (a failure part way
        # leaves some of each): the next edit rewrites them all
        self._held[0] = (out, coloured | before)
        todo = np.flatnonzero(redo).astype(np.int32)
        peaks = np.zeros((max(len(todo), 1), 27), np.uint8)
        box = np.zeros((max(len(todo), 1), 6), np.int32)
        lut = np.ascontiguousarray(spec.data_tf.lut, dtype=np.float32)
        table = step_table(spec, w.steps, w.n_steps)
        q, cpu = self.dc.queue, self.dc.is_cpu
        program = self._program()
        with DeviceWork(self.dc) as work:
            out_buf = work.buffer(out, access="rw", in_place=cpu)
            if len(todo):
                kern = cl.Kernel(program, "recolour")
                runs = _runs(todo, self.grid[2])
                held = [work.buffer(a) for a in (lut, table, todo, runs)]
                held += [work.buffer(a, access="w") for a in (peaks, box)]
                kern.set_args(
                    self.u, self.k, held[0], np.int32(lut.shape[0]), held[1],
                    np.uint32(w.none), out_buf, *held[2:4], *self._shape_args(), *held[4:],
                )  # fmt: skip
                cl.enqueue_nd_range_kernel(q, kern, (len(runs) - 1,), None)
                work.read(peaks, held[4], in_place=False)
                work.read(box, held[5], in_place=False)
            work.read(out, out_buf, cpu)  # on a CPU the host pointer holds it, mapped
        # bricks not rewritten hold nothing: not coloured now, nor in the array before
        stats = np.zeros((*self.grid, 27), np.uint8)
        stats.reshape(-1, 27)[todo] = peaks[: len(todo)]
        bounds = np.array([1 << 30] * 3 + [-1] * 3, dtype=np.int32)
        filled = box[: len(todo), 3] >= 0
        if len(todo) and filled.any():
            bounds[:3] = box[: len(todo)][filled, :3].min(axis=0)
            bounds[3:] = box[: len(todo)][filled, 3:].max(axis=0)
        grid = grown_grid(stats)
        self._held[0] = (out, coloured)
        return Sparse(out, coloured, len(todo), grid, bounds)

    def held(self) -> np.ndarray | None:
        """The bricks that may be coloured in the output (None: it is not held)."""
        return self._held[0][1] if self._held else None

    def take_held(self) -> list:
        """The output array with its bricks that may be coloured, for the next winners of the
        same shape (`held`); this one recolours no more."""
        held, self._held = self._held, []
        return held

    def release(self) -> None:
        super().release()
        for b in self._own:
            b.release()
        self._own = []
        self._held = []


def aligned_zeros(shape) -> np.ndarray:
    """Zeroed uint8 of `shape`, 64-byte aligned (PoCL writes it in place), its pages touched."""
    out = aligned_empty(shape, np.uint8)
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


def takes_over(held: list | None, shape: tuple) -> bool:
    """Whether a `BrickRecolour` of winners of `shape` (Z, Y, X) writes into `held`, the
    output of the last one (`take_held`), instead of an array of its own."""
    grid = brick_grid.grid_shape(tuple(shape))
    return bool(held) and all(a.shape == (*shape, 4) and m.shape == grid for a, m in held)


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
    from chronocl.integration.inmemory import make_spec

    block = aligned_empty((2, B, B, B), dtype)
    block[...] = 0
    t_index = aligned_empty((B, B, B), np.int32)
    t_index[...] = 1
    for mode in ("max", "change"):  # change's gather is a kernel of its own
        spec = make_spec(mode)
        w = gather(t_index, {0: block[0], 1: block[1]}, (0, 1), 2, (0.0, 1.0), spec, device)
        volume = BrickRecolour(w, device)
        try:
            volume.sparse(spec)
        finally:
            volume.release()
