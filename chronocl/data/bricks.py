"""Bricks: the rows of a window's steps that an engine integrates, and where they come from.

Integration is independent per z-slab: a slab [z0, z1) is read as [r0, r1) = [z0 - halo,
z1 + halo] clipped to the volume, integrated, and its halo rows cropped. A brick is those
rows of the window's W steps in xytz order: (r1 - r0, W, Y, X).

A `BrickSource` gives bricks: `read(steps, z0, z1)`. Every integration path takes one:
`SeriesBricks` reads a `TimeSeries` (decoding a store straight into reused buffers), and
`ResidentBricks` stacks whole steps already in memory (the window manager's, a session's).
"""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.core.memory import aligned_empty
from chronocl.data.timeseries import STEPS_PER_READ, TimeSeries


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


class BrickSource(Protocol):
    """Where bricks come from. A brick returned stays valid until two more reads (a source
    may reuse its buffers in turn: one brick integrated while the next is read)."""

    def read(self, steps: Sequence[int], z0: int, z1: int) -> np.ndarray:
        """Rows [z0, z1) of `steps` as an xytz brick (z1 - z0, W, Y, X)."""
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
        per_call: int = STEPS_PER_READ,
    ) -> None:
        self.series = series
        self.per_call = per_call
        self.buffers = list(buffers) if stored_z_chunk(series) else []
        self.turn = 0

    @classmethod
    def buffered(
        cls,
        series: TimeSeries,
        rows: int,
        width: int,
        count: int = 2,
        per_call: int = STEPS_PER_READ,
    ) -> SeriesBricks:
        """A source with `count` buffers of `rows` rows (fresh pages cost as much as reading:
        two where the next brick is read while one is integrated)."""
        shape = brick_shape(series, rows, width)
        n = count if stored_z_chunk(series) else 0
        return cls(series, [aligned_empty(shape, series.dtype) for _ in range(n)], per_call)

    @classmethod
    def per_thread(
        cls, series: TimeSeries, rows: int, width: int, per_call: int = STEPS_PER_READ
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

    def read(self, steps: Sequence[int], z0: int, z1: int) -> np.ndarray:
        if not self.buffers:
            return self.series.read_brick(steps, z0, z1)
        brick = self.buffers[self.turn][: z1 - z0]
        self.turn = (self.turn + 1) % len(self.buffers)
        return self.series.read_brick(steps, z0, z1, out=brick, per_call=self.per_call)


_held = threading.local()  # SeriesBricks.per_thread: a worker may run one task per thread


def brick_shape(series: TimeSeries, rows: int, width: int) -> tuple[int, int, int, int]:
    """The shape of a brick of `rows` rows (at most the volume's) of `width` steps."""
    nz, ny, nx = series.volume_shape
    return min(rows, nz), width, ny, nx


class ResidentBricks:
    """Bricks stacked from whole steps held in memory: {step: (Z, Y, X) array}.

    With `keep` the last brick is kept and served again for the same steps and rows: an
    interactive session re-integrating one window under a new transfer function then stacks
    nothing (at 256^3 the stacking copy costs more than the kernel).
    """

    def __init__(self, arrays: Mapping[int, np.ndarray], keep: bool = False) -> None:
        self.arrays = arrays
        self.keep = keep
        self._kept: tuple[tuple, np.ndarray] | None = None

    def read(self, steps: Sequence[int], z0: int = 0, z1: int | None = None) -> np.ndarray:
        key = (tuple(int(s) for s in steps), z0, z1)
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
    for i, a in enumerate(arrays):
        out[:, i] = a[z0:z1]
    return out
