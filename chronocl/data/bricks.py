"""Bricks: the rows of a window's steps that an engine integrates, and where they come from.

Integration is independent per z-slab: a slab [z0, z1) is read as [r0, r1) = [z0 - halo,
z1 + halo] clipped to the volume, integrated, and its halo rows cropped. A brick is those
rows of the window's W steps in xytz order: (r1 - r0, W, Y, X).

A `BrickSource` gives bricks: `read(steps, z0, z1)`. Every integration path takes one:
`SeriesBricks` reads a `TimeSeries` (decoding a store straight into reused buffers), and
`ResidentBricks` serves whole steps already in memory (the window manager's, a session's), and
`PartlyResidentBricks` a window of which only some steps are (the rest read from the series).

Steps already in memory are not stacked where they lie in one block of memory (an in-memory
series' array, the window manager's slots): a `SlotBrick` names them where they are, and an
engine that reads host memory in place (OpenCL on a CPU device) integrates them without a
copy. Any other reader gets the stacked brick from `numpy.asarray`.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.core.host_threads import copy_all
from chronocl.core.memory import ALIGN, aligned_empty
from chronocl.core.tuning import TUNING
from chronocl.data.timeseries import TimeSeries


@dataclass(frozen=True)
class Slab:
    z0: int  # first output row
    z1: int  # one past the last output row
    r0: int  # first row read (z0 minus halo, clipped)
    r1: int  # one past the last row read

    @property
    def crop(self) -> slice:
        """Rows of the read block that belong to the output."""
        return slice(self.z0 - self.r0, self.z1 - self.r0)

    @property
    def bounds(self) -> tuple[int, int, int, int]:
        """(z0, z1, r0, r1): what a slab is when it travels (`Slab(*bounds)` again)."""
        return self.z0, self.z1, self.r0, self.r1


def slabs(nz: int, slab: int, halo: int = 0) -> list[Slab]:
    """Cover [0, nz) with slabs of `slab` rows (the last may be shorter)."""
    if slab < 1:
        raise InvalidParameterError(f"slab size must be at least 1 row, got {slab}")
    if halo < 0:
        raise InvalidParameterError(f"halo must be >= 0, got {halo}")
    out = []
    for z0 in range(0, nz, slab):
        z1 = min(z0 + slab, nz)
        out.append(Slab(z0, z1, max(0, z0 - halo), min(nz, z1 + halo)))
    return out


@dataclass(frozen=True, eq=False)
class SlotBrick:
    """An xytz brick (rows, W, Y, X) left where its steps lie: in the flat `block`, voxel
    (z, i, y, x) of brick step i is at `offsets[i] + z * zstride + y * X + x` (the steps of an
    in-memory series, whose rows follow one another; the window manager's slots, whose rows
    interleave with the other slots'). `holds` keeps the step arrays it was made from alive
    while it is in use: the window manager reuses a slot only once nothing holds its step."""

    block: np.ndarray  # 1-D, the steps' dtype
    offsets: np.ndarray  # int64, one per step of the brick
    zstride: int  # elements from one row of a step to its next
    shape: tuple[int, int, int, int]
    holds: tuple = ()

    @property
    def dtype(self) -> np.dtype:
        return self.block.dtype

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * self.dtype.itemsize

    def step(self, i: int) -> np.ndarray:
        """The rows of brick step i (rows, Y, X), a view."""
        rows, _, ny, nx = self.shape
        item = self.dtype.itemsize
        start = self.block[int(self.offsets[i]) :]
        return np.lib.stride_tricks.as_strided(
            start, (rows, ny, nx), (self.zstride * item, nx * item, item), writeable=False
        )

    def rows(self, r0: int, r1: int) -> SlotBrick:
        """Brick rows [r0, r1) as a brick whose block spans only them, starting on a 64-byte
        boundary where the memory allows (16-lane loads need no fix-up)."""
        ny, nx = self.shape[2:]
        first = self.offsets + r0 * self.zstride
        lo = int(first.min())
        lo -= min(lo, self.block[lo:].ctypes.data % ALIGN // self.dtype.itemsize)
        hi = int(first.max()) + (r1 - r0 - 1) * self.zstride + ny * nx
        rows = (r1 - r0, self.shape[1], ny, nx)
        return SlotBrick(self.block[lo:hi], first - lo, self.zstride, rows, self.holds)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = aligned_empty(self.shape, self.dtype)
        copy_all([(out[:, i], self.step(i)) for i in range(self.shape[1])])
        return out if dtype is None else out.astype(dtype, copy=False)


def slot_brick(
    arrays: Sequence[np.ndarray], z0: int = 0, z1: int | None = None
) -> SlotBrick | None:
    """Rows [z0, z1) of whole-volume step arrays (Z, Y, X) as a `SlotBrick`, where all of them
    lie in the memory of one C-contiguous array, each with contiguous rows and the same row
    stride; else None (stack them)."""
    first = arrays[0]
    root = _owner(first)
    dt, shape, item = first.dtype, first.shape, first.dtype.itemsize
    nz, ny, nx = shape
    zs = first.strides[0]
    if not root.flags.c_contiguous or zs <= 0 or zs % item:
        return None
    for a in arrays:
        if (
            a.shape != shape
            or a.dtype != dt
            or a.strides[1:] != (nx * item, item)
            or (nz > 1 and a.strides[0] != zs)
            or _owner(a) is not root
        ):
            return None
    raw = root.reshape(-1).view(np.uint8)
    skip = -raw.ctypes.data % item  # the first byte of root at which a `dt` element may start
    origin = raw.ctypes.data + skip
    starts = np.array([a.ctypes.data - origin for a in arrays], np.int64)
    if (starts % item).any():
        return None
    flat = raw[skip : skip + (raw.size - skip) // item * item].view(dt)
    whole = SlotBrick(flat, starts // item, zs // item, (nz, len(arrays), ny, nx), tuple(arrays))
    return whole.rows(z0, nz if z1 is None else z1)


def _owner(a: np.ndarray) -> np.ndarray:
    """The array whose memory `a` views (`a` itself if it owns its data)."""
    while isinstance(a.base, np.ndarray):
        a = a.base
    return a


class BrickSource(Protocol):
    """Where bricks come from. A brick returned stays valid until two more reads (a source
    may reuse its buffers in turn: one brick integrated while the next is read)."""

    def read(self, steps: Sequence[int], z0: int, z1: int) -> np.ndarray | SlotBrick:
        """Rows [z0, z1) of `steps` as an xytz brick (z1 - z0, W, Y, X), stacked or in place."""
        ...


def stored_z_chunk(series: TimeSeries) -> int:
    """Rows per stored chunk along z (0 for data in memory, which need no decoding)."""
    return series.z_chunk if getattr(series, "_zarr", None) is not None else 0


class SeriesBricks:
    """Bricks read from a `TimeSeries`: into the `buffers` given, in turn, where the series
    decodes a store (zarr decodes the rows straight into the brick, `per_call` steps per
    call); a fresh brick per read for data in memory or without buffers."""

    def __init__(
        self,
        series: TimeSeries,
        buffers: Sequence[np.ndarray] = (),
        per_call: int | None = None,  # None: TUNING.steps_per_read
    ) -> None:
        self.series = series
        self.per_call = TUNING.steps_per_read if per_call is None else per_call
        self.buffers = list(buffers) if stored_z_chunk(series) else []
        self.turn = 0

    @classmethod
    def buffered(
        cls,
        series: TimeSeries,
        rows: int,
        width: int,
        count: int = 2,
        per_call: int | None = None,
    ) -> SeriesBricks:
        """A source with `count` buffers of `rows` rows (fresh pages cost as much as reading:
        two where the next brick is read while one is integrated)."""
        shape = brick_shape(series, rows, width)
        n = count if stored_z_chunk(series) else 0
        return cls(series, [aligned_empty(shape, series.dtype) for _ in range(n)], per_call)

    @classmethod
    def per_thread(
        cls, series: TimeSeries, rows: int, width: int, per_call: int | None = None
    ) -> SeriesBricks:
        """A source whose one buffer stays with the calling thread from call to call (a dask
        worker's thread runs task after task), grown to the largest brick asked for."""
        _, ny, nx = series.volume_shape
        key = (series.dtype.str, width, ny, nx)
        held = getattr(_held, "bricks", {}).get(key)
        if held is None or held.shape[0] < rows:
            held = aligned_empty(brick_shape(series, rows, width), series.dtype)
            _held.bricks = {key: held}
        return cls(series, [held], per_call)

    def read(self, steps: Sequence[int], z0: int, z1: int) -> np.ndarray | SlotBrick:
        host = self.series.host
        if host is not None:
            brick = slot_brick([host[int(s)] for s in steps], z0, z1)
            if brick is not None:
                return brick
        if not self.buffers:
            return self.series.read_brick(steps, z0, z1)
        brick = self.buffers[self.turn][: z1 - z0]
        self.turn = (self.turn + 1) % len(self.buffers)
        return self.series.read_brick(steps, z0, z1, out=brick, per_call=self.per_call)


_held = threading.local()  # SeriesBricks.per_thread: a worker may run one task per thread


class PartlyResidentBricks:
    """Bricks of a window some of whose steps are resident ({step: (Z, Y, X) array}): their
    rows copied, the other steps' read from the series into the same brick (a window that
    only partly fits the memory limit: `chronocl.integration.interactive.session`)."""

    def __init__(self, series: TimeSeries, arrays: Mapping[int, np.ndarray]) -> None:
        self.series = series
        self.arrays = arrays

    def read(self, steps: Sequence[int], z0: int, z1: int) -> np.ndarray:
        steps = [int(s) for s in steps]
        out = aligned_empty(brick_shape(self.series, z1 - z0, len(steps)), self.series.dtype)
        i = 0
        while i < len(steps):  # each run of steps not resident in one read
            j = i
            while j < len(steps) and steps[j] not in self.arrays:
                j += 1
            if j > i:
                self.series.read_brick(steps[i:j], z0, z1, out=out[:, i:j])
            i = j + 1
        copy_all(
            [(out[:, i], self.arrays[s][z0:z1]) for i, s in enumerate(steps) if s in self.arrays]
        )
        return out


def brick_shape(series: TimeSeries, rows: int, width: int) -> tuple[int, int, int, int]:
    """The shape of a brick of `rows` rows (at most the volume's) of `width` steps."""
    nz, ny, nx = series.volume_shape
    return min(rows, nz), width, ny, nx


class ResidentBricks:
    """Bricks of whole steps held in memory: {step: (Z, Y, X) array}, in place where they lie
    in one block of memory (`slot_brick`), else stacked.

    `in_place` False always stacks, for an engine that cannot read host memory in place (a
    GPU's, the numpy reference). With its `keep` attribute set (an interactive session sets it)
    the last stacked brick is kept and served again for the same steps and rows: an interactive
    session re-integrating one window under a new transfer function then stacks nothing (at
    256^3 the stacking copy costs more than the kernel).
    """

    def __init__(self, arrays: Mapping[int, np.ndarray], in_place: bool = True) -> None:
        self.arrays = arrays
        self.keep = False
        self.in_place = in_place  # False: an engine that would stack a SlotBrick itself
        self._kept: tuple[tuple, np.ndarray] | None = None

    def read(
        self, steps: Sequence[int], z0: int = 0, z1: int | None = None
    ) -> np.ndarray | SlotBrick:
        if self.in_place:
            brick = slot_brick([self.arrays[int(s)] for s in steps], z0, z1)
            if brick is not None:
                return brick
        key = (tuple(int(s) for s in steps), z0, z1)
        one = self.arrays[key[0][0]]
        if len(key[0]) == 1 and one.flags.c_contiguous:  # a (rows, 1, Y, X) view, no copy
            return one[z0:z1, None]
        if self._kept is not None:
            if self._kept[0] == key and self.keep:
                return self._kept[1]
            self._kept = None  # freed before the next brick is stacked
        brick = stack_brick([self.arrays[s] for s in key[0]], z0, z1)
        if self.keep:
            self._kept = (key, brick)
        return brick

    def forget(self) -> None:
        """Drop the kept brick (its steps are no longer resident)."""
        self._kept = None


def stack_brick(arrays: Sequence[np.ndarray], z0: int = 0, z1: int | None = None) -> np.ndarray:
    """Rows [z0, z1) of whole-volume step arrays (Z, Y, X) as an xytz brick (z1 - z0, W, Y, X)."""
    first = arrays[0]
    z1 = first.shape[0] if z1 is None else z1
    out = aligned_empty((z1 - z0, len(arrays), *first.shape[1:]), first.dtype)
    copy_all([(out[:, i], a[z0:z1]) for i, a in enumerate(arrays)])
    return out
