"""A window's steps resident on an OpenCL device, so an edit of the transfer function uploads
nothing and a slide uploads only the entering step.

`DeviceSteps` is one device buffer of `count` step slots laid out (Z, S, Y, X), as the kernels'
SLOTS build reads them (common.h's VOX_INDEX: a table of each step's offset and a row stride),
so a window integrates from the slots its steps occupy, in any order, without a copy on the
device either. Steps are kept by index until their slot is needed (least recently used first):
scrubbing back finds them still there. `DeviceBricks` is the brick source a session integrates
from: it uploads what is missing and hands the engine a `DeviceBrick`.

Only engines that copy bricks use it (a GPU; a CPU device reads host memory in place, where a
second copy would double the memory). The device budget is a share of the device's global
memory (`DEVICE_SHARE`, or ``CHRONOCL_DEVICE_MEMORY``); a window that does not fit is streamed
from the host as before, and the session says so. A session's sliding state, kept on the device
too, holds its bytes from the same budget (`reserve`).
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from chronocl.core import env
from chronocl.core.budget import human, parse_memory
from chronocl.engine.buffers import DeviceLimitError, DeviceWork, buffer, max_alloc
from chronocl.engine.device_arrays import on_device
from chronocl.engine.device_formats import stored_dtype

DEVICE_SHARE = 0.6  # of the device's global memory, for resident steps (the rest: outputs, tables)
SPARE_SLOTS = 2  # beyond the window: the steps a slide or a scrub back needs next


# Bytes of device slots held per device context, by every session of the process: the budget
# is the device's, shared by the views and levels that each keep their window there.
_held: dict[int, int] = {}
# Reentrant: holds and slots that die in reference cycles give back from within a garbage
# collection, which any allocation under the lock may start in the thread holding it.
_lock = threading.RLock()


def _give_back(dc_id: int, nbytes: int) -> None:
    with _lock:
        _held[dc_id] = _held.get(dc_id, 0) - nbytes


def budget_left(dc) -> int:
    """The device budget less what other sessions' slots on `dc` hold now."""
    with _lock:
        held = _held.get(id(dc), 0)
    return max(0, device_budget(dc.info.global_mem) - held)


def device_budget(global_mem: int) -> int:
    """Bytes of device memory resident steps may take: ``CHRONOCL_DEVICE_MEMORY`` when set
    (e.g. "6GB"), else `DEVICE_SHARE` of the device's global memory."""
    given = env.get("CHRONOCL_DEVICE_MEMORY")
    return parse_memory(given) if given else int(global_mem * DEVICE_SHARE)


def reserve(dc, nbytes: int):
    """Hold `nbytes` of the device budget of `dc` for something other than step slots (a
    sliding window's partials and sums), or None where the budget has not that much left.
    The hold is given back when the returned handle is called or collected."""
    budget = device_budget(dc.info.global_mem)
    with _lock:
        if budget - _held.get(id(dc), 0) < nbytes:
            return None
        _held[id(dc)] = _held.get(id(dc), 0) + nbytes
    return Hold(id(dc), nbytes)


class Hold:
    """Bytes of a device budget held until called (or collected): see `reserve`."""

    def __init__(self, dc_id: int, nbytes: int) -> None:
        self.nbytes = nbytes
        self._give_back = weakref.finalize(self, _give_back, dc_id, nbytes)

    def __call__(self) -> None:
        self._give_back()


@dataclass(frozen=True)
class DeviceBrick:
    """Brick rows (rows, W, Y, X) whose steps lie in a device buffer: voxel (z, i, y, x) of
    brick step i at element `offsets[i] + z * zstride + y * X + x`."""

    buffer: object  # a pyopencl Buffer
    offsets: np.ndarray  # int64, one per step
    zstride: int
    shape: tuple[int, int, int, int]
    dtype: np.dtype

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * self.dtype.itemsize


class DeviceSteps:
    """`count` step slots of `shape` (Z, Y, X) and `dtype` in one buffer on the device of `dc`
    (a `chronocl.engine.device.DeviceContext`)."""

    def __init__(self, dc, shape: tuple[int, int, int], dtype: np.dtype, count: int) -> None:
        self.dc, self.shape, self.dtype, self.count = dc, tuple(shape), np.dtype(dtype), count
        nz, ny, nx = self.shape
        self.nbytes = nz * count * ny * nx * self.dtype.itemsize
        self.buffer = buffer(dc, nbytes=self.nbytes)
        with _lock:
            _held[id(dc)] = _held.get(id(dc), 0) + self.nbytes
        self._held = weakref.finalize(self, _give_back, id(dc), self.nbytes)
        self._slot: OrderedDict[int, int] = OrderedDict()  # step -> slot, least recent first
        self.uploads = 0  # steps uploaded so far

    @classmethod
    def fitting(
        cls, dc, shape: tuple[int, int, int], dtype: np.dtype, width: int
    ) -> DeviceSteps | None:
        """Slots for a window of `width` steps and `SPARE_SLOTS` more, where they fit the
        device budget and one buffer; None where the window alone does not."""
        step = int(np.prod(shape)) * np.dtype(dtype).itemsize
        room = min(budget_left(dc), max_alloc(dc)) // max(1, step)
        if room < width:
            return None
        return cls(dc, shape, dtype, min(room, width + SPARE_SLOTS))

    def resident(self) -> list[int]:
        return list(self._slot)

    def touch(self, steps: Sequence[int]) -> None:
        """Mark the resident ones of `steps` used now, in their order (a window that slid: the
        steps that left it give their slots up first, though a slide read them last)."""
        for s in steps:
            if int(s) in self._slot:
                self._slot.move_to_end(int(s))

    def release(self) -> None:
        """Free the device buffer now (the slots are not used again)."""
        self.buffer.release()
        self._slot.clear()
        self._held()  # counted off the device's budget once

    def brick(self, arrays: Mapping[int, np.ndarray], steps: Sequence[int], z0: int, z1: int):
        """Rows [z0, z1) of `steps` as a `DeviceBrick`, uploading from `arrays` ({step: (Z, Y,
        X) array}) the steps not resident yet, into the least recently used free slots."""
        steps = [int(s) for s in steps]
        if len(set(steps)) > self.count:
            raise ValueError(f"{len(set(steps))} steps do not fit {self.count} device slots")
        for s in steps:
            if s in self._slot:
                self._slot.move_to_end(s)
        missing = [s for s in dict.fromkeys(steps) if s not in self._slot]
        free = sorted(set(range(self.count)) - set(self._slot.values()))
        for s in missing:
            if free:
                slot = free.pop(0)
            else:  # the least recently used step not in this brick gives its slot up
                old = next(t for t in self._slot if t not in steps)
                slot = self._slot.pop(old)
            self._upload(arrays[s], slot)
            self._slot[s] = slot
        _, ny, nx = self.shape
        offsets = np.array([self._slot[s] * ny * nx for s in steps], np.int64)
        zstride = self.count * ny * nx
        return DeviceBrick(
            self.buffer, offsets + z0 * zstride, zstride, (z1 - z0, len(steps), ny, nx), self.dtype
        )

    def _upload(self, a: np.ndarray, slot: int) -> None:
        """Step array `a` (Z, Y, X) into `slot`: one copy per z-row (each row is contiguous on
        the host however the step lies there: a slot of the host's own block, or an array)."""
        import pyopencl as cl

        if a.shape != self.shape or a.dtype != self.dtype:
            raise ValueError(f"step of {a.dtype} {a.shape}; slots of {self.dtype} {self.shape}")
        nz, ny, nx = self.shape
        row = ny * nx * self.dtype.itemsize
        with DeviceWork(self.dc) as work:
            for z in range(nz):
                src = work.hold(np.ascontiguousarray(a[z]))
                at = (z * self.count + slot) * row
                cl.enqueue_copy(self.dc.queue, self.buffer, src, dst_offset=at, is_blocking=False)
        self.uploads += 1


class DeviceBricks:
    """A brick source over steps in memory ({step: array}, as `ResidentBricks`) that keeps them
    resident on the device (`DeviceSteps`): each read uploads only the steps not there yet."""

    def __init__(self, arrays: Mapping[int, np.ndarray], slots: DeviceSteps) -> None:
        self.arrays = arrays
        self.slots = slots

    def read(self, steps: Sequence[int], z0: int = 0, z1: int | None = None) -> DeviceBrick:
        return self.slots.brick(self.arrays, steps, z0, self.slots.shape[0] if z1 is None else z1)


def run_resident(work, brick: DeviceBrick, outputs: list, launch, chunk, z0: int) -> None:
    """Launch the kernels (`launch(queue, data, chunk, out_buffers)`, the engine's) of brick
    rows `chunk` of a resident brick into device buffers, and enqueue their read-back into
    rows chunk.a - z0 .. chunk.b - z0 of the host `outputs` (`work`: the engine's
    `chronocl.engine.buffers.DeviceWork`); device arrays among `outputs` (a sliding window's
    leaves) are written where they are, whole."""
    rows = [a if on_device(a) else a[chunk.a - z0 : chunk.b - z0] for a in outputs]
    if any(on_device(a) for a in outputs) and chunk.b - chunk.a != outputs[0].shape[0]:
        raise DeviceLimitError("a device output over the device's largest buffer")
    bufs = [a.data if on_device(a) else work.buffer(a, access="w") for a in rows]
    launch(work.queues[0], brick.buffer, chunk, bufs)
    for a, b in zip(rows, bufs, strict=True):
        if not on_device(a):
            work.read(a, b, in_place=False)


class DeviceWindow:
    """A session's steps on its engine's device: slots for its window, made again for a wider
    one. `bricks` is None where the steps stay on the host (a CPU device reads them in place;
    bricks that travel converted, float64 integrated as float32; a window over what the device
    budget has left beside the other sessions' slots: `why` then says so)."""

    def __init__(self, engine, series) -> None:
        copies = engine.copies_to_device
        as_stored = stored_dtype(series.dtype) == series.dtype
        keeps = copies and as_stored and engine.device_format == "auto"
        self.engine = engine if keeps else None
        self.shape, self.dtype = tuple(series.volume_shape), np.dtype(series.dtype)
        self.slots: DeviceSteps | None = None
        self.why: str | None = None

    def bricks(self, arrays: Mapping[int, np.ndarray], width: int) -> DeviceBricks | None:
        if self.engine is None:
            return None
        if self.slots is None or self.slots.count < width:
            self.release()  # freed before a wider one is made
            dc = self.engine.dc
            try:
                self.slots = DeviceSteps.fitting(dc, self.shape, self.dtype, width)
            except MemoryError:  # pyopencl's allocation failure is a MemoryError too
                self.slots = None
            if self.slots is None:
                need = width * int(np.prod(self.shape)) * self.dtype.itemsize
                room = budget_left(dc)
                self.why = (
                    f"the window needs {human(need)} of device memory, {human(room)} is free "
                    "for steps: they are sent from the host for every integration"
                )
                return None
        self.why = None
        return DeviceBricks(arrays, self.slots)

    def release(self) -> None:
        if self.slots is not None:
            self.slots.release()
            self.slots = None
