"""Host-to-device transfers of bricks: the format a brick travels in, and overlapped uploads.

On a GPU the PCIe transfer of a brick, not the kernel, bounds an integration. Two things cut
it (docs/engine.md, "Transfers and device formats"):

* **Device formats** (`DeviceFormat`, `resolve_format`): a brick may travel narrower than it is
  stored. ``auto`` sends the stored type (float64 as float32), ``float32`` float32 (integers
  widened, a baseline), ``float16`` halves float32 traffic, ``uint8`` / ``uint16`` quantise
  the values over the normalising value range. The kernels see quantised data as integers
  whose value range is (0, 255) or (0, 65535), so every mode works on them unchanged.
* **Overlap** (`run_chunks`): a brick is cut into chunks of output rows (with their gradient
  halo); chunk i+1 is encoded into a pinned host staging buffer (``CL_MEM_ALLOC_HOST_PTR``,
  mapped) and uploaded on one queue while the kernel of chunk i runs on a second and the result
  of chunk i-1 is read back on a third. Two device buffers of each kind are used in turn; events
  order the reuse: an upload into a buffer waits for the kernel that last read it, a kernel
  waits for its upload and for the read-back of the output buffer it writes.

Timings come from OpenCL profiling events (`TransferStats`).
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError

FORMATS = ("auto", "float32", "uint8", "uint16", "float16")
QUANT_MAX = {"uint8": 255, "uint16": 65535}
HALF_MAX = 65504.0  # the largest finite float16
HALF_EPS = 2.0**-11  # float16 rounding: relative error of a normal value
MIN_CHUNK, MAX_CHUNK = 4 << 20, 64 << 20  # bytes of one transfer chunk (auto sizing)
PARALLEL_MIN = 1 << 18  # values from which a conversion is split over threads


def _workers() -> int:
    return min(8, os.cpu_count() or 1)


_pool_lock = threading.Lock()
_pool_held: list[ThreadPoolExecutor] = []


def _pool() -> ThreadPoolExecutor:
    """The threads that convert bricks on the host (made when first needed)."""
    with _pool_lock:
        if not _pool_held:
            _pool_held.append(
                ThreadPoolExecutor(max_workers=_workers(), thread_name_prefix="chronocl-encode")
            )
        return _pool_held[0]


def stored_dtype(dtype: np.dtype) -> np.dtype:
    """The dtype a brick of `dtype` is integrated in (float64 as float32, like the reference)."""
    return np.dtype(np.float32) if np.dtype(dtype) == np.float64 else np.dtype(dtype)


@dataclass(frozen=True)
class DeviceFormat:
    """How a brick of `source` values travels to the device.

    `dtype` is what the device receives; `quant_max` is 255 or 65535 when the values are
    quantised over `value_range` (the range that normalises them to u), else 0.
    """

    name: str
    source: np.dtype
    dtype: np.dtype
    value_range: tuple[float, float]
    quant_max: int = 0

    @property
    def converts(self) -> bool:
        """Whether bricks are converted on the host before they travel."""
        return self.dtype != self.source

    @property
    def device_range(self) -> tuple[float, float]:
        """The value range the kernels normalise the device values with."""
        if not self.quant_max:
            return self.value_range
        lo, hi = self.value_range
        return (0.0, float(self.quant_max)) if hi > lo else (0.0, 0.0)

    @property
    def max_error(self) -> float:
        """The largest error in u (a fraction of the value range) values inside the range get:
        half a quantisation step, float16 rounding of the largest magnitude, or 0."""
        lo, hi = self.value_range
        if not hi > lo or not self.converts:
            return 0.0
        if self.quant_max:
            return 0.5 / self.quant_max
        if self.dtype == np.float16 and self.source.kind == "f":
            return max(abs(lo), abs(hi)) * HALF_EPS / (hi - lo)
        return 0.0

    def encode(self, src: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """`src` as the device receives it (into `out`, same shape, when given).

        Large bricks are split over threads (numpy releases the GIL): converting on the host
        runs at 2-15 ns per value on one core, slower than PCIe moves the bytes saved, and one
        core's copy into the staging buffer is slower than a PCIe 4/5 link too.
        """
        if out is None:
            out = np.empty(src.shape, self.dtype)
        parts = _workers() if src.size >= PARALLEL_MIN else 1
        if parts > 1 and src.flags.c_contiguous and out.flags.c_contiguous:
            flat_src, flat_out = src.reshape(-1), out.reshape(-1)
            bounds = np.linspace(0, src.size, parts + 1).astype(int)
            pieces = [slice(a, b) for a, b in itertools.pairwise(bounds)]
            list(_pool().map(lambda p: self._encode(flat_src[p], flat_out[p]), pieces))
            return out
        return self._encode(src, out)

    def _encode(self, src: np.ndarray, out: np.ndarray) -> np.ndarray:
        if not self.converts:
            np.copyto(out, src)
        elif self.quant_max:
            out[...] = quantize(src, self.value_range, self.quant_max)
        elif self.dtype == np.float16:
            # Saturating: a value past float16's range becomes its largest finite value, which
            # normalises like the clipped value would (the range itself fits float16).
            np.clip(src, -HALF_MAX, HALF_MAX, out=out, casting="unsafe")
        else:
            out[...] = src
        return out


def quantize(values: np.ndarray, value_range: tuple[float, float], q_max: int) -> np.ndarray:
    """Values clipped to `value_range` and mapped linearly onto 0..q_max, rounded to nearest, in
    float32 arithmetic: q = rint((clip(v) - vmin) * (q_max / (vmax - vmin))). A constant range
    gives 0 everywhere. The result is float32 holding whole numbers."""
    lo, hi = value_range
    v = np.asarray(values, dtype=np.float32)
    if not hi > lo:
        return np.zeros(v.shape, np.float32)
    lo32, hi32 = np.float32(lo), np.float32(hi)
    q = (np.clip(v, lo32, hi32) - lo32) * np.float32(q_max / (float(hi) - float(lo)))
    np.rint(q, out=q)
    return np.clip(q, np.float32(0), np.float32(q_max), out=q)


def check_format_name(name: str) -> str:
    """A device format chronocl has (checked before any work)."""
    if name not in FORMATS:
        raise UnknownNameError(
            f"unknown device format {name!r}; choose one of {', '.join(FORMATS)}"
        )
    return name


def resolve_format(name: str, dtype: np.dtype, value_range: tuple[float, float]) -> DeviceFormat:
    """The device format `name` for data stored as `dtype`, normalised over `value_range`.

    Refuses (one line, InvalidParameterError) a format that would not make the brick smaller
    than it is stored and is lossy or wider (uint16 or float16 for uint8 data, float16 or uint16
    for 16-bit integers), and float16 where it cannot hold the range or resolves it more
    coarsely than uint8 would.
    """
    check_format_name(name)
    src = stored_dtype(dtype)
    lo, hi = float(value_range[0]), float(value_range[1])
    if name == "auto":
        return DeviceFormat(name, src, src, (lo, hi))
    if name == "float32":  # integer data widened: a baseline to compare the compact formats with
        return DeviceFormat(name, src, np.dtype(np.float32), (lo, hi))
    target = np.dtype(name)
    if target == src:
        return DeviceFormat(name, src, src, (lo, hi))
    if target.itemsize >= src.itemsize:
        raise InvalidParameterError(
            f"--device-format {name} would send {src.name} data in {target.itemsize} bytes per "
            f"value, not fewer than the {src.itemsize} they are stored in; use auto"
        )
    if name == "float16":
        big = max(abs(lo), abs(hi))
        if big > HALF_MAX:
            raise InvalidParameterError(
                f"--device-format float16 cannot hold the value range {lo:g}..{hi:g} (float16 "
                f"ends at {HALF_MAX:g}); use uint16 (quantised over the range) or auto"
            )
        fmt = DeviceFormat(name, src, target, (lo, hi))
        if fmt.max_error > 0.5 / QUANT_MAX["uint8"]:
            raise InvalidParameterError(
                f"--device-format float16 resolves values near {big:g} only to "
                f"{big * HALF_EPS:.3g}, {100 * fmt.max_error:.2g}% of the value range "
                f"{lo:g}..{hi:g} (coarser than uint8); use uint16 or auto"
            )
        return fmt
    return DeviceFormat(name, src, target, (lo, hi), QUANT_MAX[name])


# -- overlapped transfers --------------------------------------------------------------------


@dataclass
class TransferStats:
    """Timings of one brick sent through the device (seconds, from profiling events where the
    queues profile; `wall_s` from the first upload's start to the last read-back's end)."""

    chunks: int
    overlapped: bool
    upload_bytes: int
    download_bytes: int
    upload_s: float | None = None
    kernel_s: float | None = None
    download_s: float | None = None
    wall_s: float | None = None
    host_s: float = 0.0  # encoding into the staging buffers, on the host

    @property
    def transfer_s(self) -> float | None:
        """Seconds the copies took (uploads and read-backs)."""
        if self.upload_s is None or self.download_s is None:
            return None
        return self.upload_s + self.download_s

    @property
    def overlap(self) -> float | None:
        """wall / max(kernel, transfer): 1.0 when the copies hide entirely behind the kernels
        (or the reverse), 2.0 when nothing overlaps, more when the device waited for the host."""
        t, k, w = self.transfer_s, self.kernel_s, self.wall_s
        if t is None or k is None or w is None or max(k, t) <= 0:
            return None
        return w / max(k, t)

    def to_dict(self) -> dict:
        return {
            "chunks": self.chunks,
            "overlapped": self.overlapped,
            "upload_bytes": self.upload_bytes,
            "download_bytes": self.download_bytes,
            "upload_s": self.upload_s,
            "download_s": self.download_s,
            "transfer_s": self.transfer_s,
            "kernel_s": self.kernel_s,
            "wall_s": self.wall_s,
            "host_s": self.host_s,
            "overlap": self.overlap,
        }


@dataclass(frozen=True)
class Chunk:
    """Output rows [a, b) of a brick and the brick rows [r0, r1) they need (with halo)."""

    a: int
    b: int
    r0: int
    r1: int

    @property
    def zcrop(self) -> int:
        """The chunk's first output row among its brick rows (kernel argument `zcrop`)."""
        return self.a - self.r0

    @property
    def rows(self) -> int:
        return self.r1 - self.r0


def chunks_of(
    nzb: int, crop: slice, halo: int, row_bytes: int, chunk_bytes: int | None
) -> list[Chunk]:
    """Cut brick rows `crop` (of `nzb`) into chunks of about `chunk_bytes` (None: the brick's
    eighth, kept within 4-64 MiB; 0: one chunk), each with up to `halo` rows either side.

    A chunk's first and last rows are halo rows or the brick's own edge rows, so the kernels'
    gradients (one-sided only at a brick's edge) are those of the whole brick. Rows here are
    brick rows; `a`, `b` are brick rows too.
    """
    z0, z1 = crop.start, crop.stop
    n = z1 - z0
    if chunk_bytes is None:
        chunk_bytes = int(np.clip(nzb * row_bytes // 8, MIN_CHUNK, MAX_CHUNK))
    per = n if chunk_bytes == 0 else max(1, chunk_bytes // max(1, row_bytes) - 2 * halo)
    out = []
    for a in range(z0, z1, per):
        b = min(a + per, z1)
        out.append(Chunk(a, b, max(0, a - halo), min(nzb, b + halo)))
    return out


@dataclass
class Streams:
    """The queues of overlapped transfers on one device (upload, compute, read-back) and the
    pinned staging and device buffers they reuse from brick to brick."""

    upload: object
    compute: object
    download: object
    profiling: bool
    buffers: dict = field(default_factory=dict)

    def buffer(self, ctx, key: str, nbytes: int, flags: int):
        """A cached device buffer of at least `nbytes` (grown, never shrunk)."""
        import pyopencl as cl

        held = self.buffers.get(key)
        if held is None or held.size < nbytes:
            self.buffers.pop(key, None)
            held = cl.Buffer(ctx, flags, max(1, nbytes))
            self.buffers[key] = held
        return held

    def staging(self, ctx, key: str, nbytes: int) -> np.ndarray:
        """A pinned host buffer (ALLOC_HOST_PTR) of at least `nbytes`, mapped once and kept
        mapped: a byte array the host writes a chunk into before it is uploaded."""
        import pyopencl as cl

        held = self.buffers.get(key)
        if held is None or held.nbytes < nbytes:
            self.buffers.pop(key, None)
            if held is not None:
                held.base.release(self.upload)
            mf = cl.mem_flags
            buf = cl.Buffer(ctx, mf.READ_ONLY | mf.ALLOC_HOST_PTR, max(1, nbytes))
            held, _ = cl.enqueue_map_buffer(
                self.upload,
                buf,
                cl.map_flags.WRITE,
                0,
                (max(1, nbytes),),
                np.uint8,
                is_blocking=True,
            )
            self.buffers[key] = held
        return held


def make_streams(context, device) -> Streams:
    """Three in-order queues, profiling where the device can."""
    import pyopencl as cl

    try:
        props = cl.command_queue_properties.PROFILING_ENABLE
        queues = [cl.CommandQueue(context, device, properties=props) for _ in range(3)]
        profiling = True
    except cl.Error:  # pragma: no cover - every device we know profiles
        queues = [cl.CommandQueue(context, device) for _ in range(3)]
        profiling = False
    return Streams(*queues, profiling=profiling)


# The kernel launches of one chunk: (queue, device brick, chunk, device outputs, wait_for)
# -> the events of its launches.
Launch = Callable[[object, object, Chunk, list, list], list]


def run_chunks(
    streams: Streams,
    context,
    fmt: DeviceFormat,
    brick: np.ndarray,
    chunks: Sequence[Chunk],
    crop_start: int,
    outputs: Sequence[np.ndarray],
    launch: Launch,
    overlap: bool = True,
    log: list | None = None,
) -> TransferStats:
    """Send `brick` chunk by chunk through `launch` and read the chunks' outputs back into
    `outputs` (rows of the brick's crop, starting at brick row `crop_start`).

    With `overlap` the upload, compute and read-back queues are distinct, so chunk i+1 travels
    while chunk i is integrated; without, everything runs on one in-order queue, one command
    after the other. `log`, when given, receives (kind, chunk index, buffer slot, event) for
    every command, in the order enqueued (tests check the ordering with it).
    """
    import pyopencl as cl

    mf = cl.mem_flags
    up, comp, down = (
        (streams.upload, streams.compute, streams.download) if overlap else (streams.compute,) * 3
    )
    row_in = int(np.prod(brick.shape[1:])) * fmt.dtype.itemsize
    rows_out = [int(np.prod(o.shape[1:])) * o.dtype.itemsize for o in outputs]
    max_in = max(c.rows for c in chunks) * row_in
    max_out = max(c.b - c.a for c in chunks)
    slots = 2 if len(chunks) > 1 else 1
    staging = [streams.staging(context, f"stage{k}", max_in) for k in range(slots)]
    dev_in = [streams.buffer(context, f"in{k}", max_in, mf.READ_ONLY) for k in range(slots)]
    dev_out = [
        [
            streams.buffer(context, f"out{k}.{i}", max_out * rb, mf.WRITE_ONLY)
            for i, rb in enumerate(rows_out)
        ]
        for k in range(slots)
    ]
    uploads: list = []
    kernels: list[list] = []
    downloads: list[list] = []
    host_s = 0.0
    t0 = time.perf_counter()
    queues = list({id(x): x for x in (up, comp, down)}.values())
    try:
        for j, c in enumerate(chunks):
            k = j % slots
            if j >= slots:
                uploads[j - slots].wait()  # the staging buffer's last upload has left it
            t = time.perf_counter()
            n = c.rows * row_in
            stage = staging[k][:n].view(fmt.dtype).reshape((c.rows, *brick.shape[1:]))
            fmt.encode(brick[c.r0 : c.r1], stage)
            host_s += time.perf_counter() - t
            # An upload into a device buffer waits for the kernels that last read it.
            after = kernels[j - slots] if j >= slots else []
            ev = cl.enqueue_copy(up, dev_in[k], staging[k][:n], is_blocking=False, wait_for=after)
            uploads.append(ev)
            _note(log, "upload", j, k, ev, after)
            # A kernel waits for its upload and for the read-back of the outputs it overwrites.
            after = [ev] + (downloads[j - slots] if j >= slots else [])
            evs = launch(comp, dev_in[k], c, dev_out[k], after)
            kernels.append(evs)
            _note(log, "kernel", j, k, evs, after)
            reads = []
            for o, buf in zip(outputs, dev_out[k], strict=True):
                dst = o[c.a - crop_start : c.b - crop_start]
                reads.append(cl.enqueue_copy(down, dst, buf, is_blocking=False, wait_for=evs))
            downloads.append(reads)
            _note(log, "download", j, k, reads, evs)
            for q in queues:
                q.flush()
    finally:  # nothing may still use the reused buffers, even after an error
        for q in queues:
            q.finish()
    wall = time.perf_counter() - t0
    stats = TransferStats(
        chunks=len(chunks),
        overlapped=overlap,
        upload_bytes=sum(c.rows for c in chunks) * row_in,
        download_bytes=sum((c.b - c.a) * sum(rows_out) for c in chunks),
        host_s=host_s,
        wall_s=wall,
    )
    if streams.profiling:
        every = uploads + [e for es in kernels for e in es] + [e for es in downloads for e in es]
        stats.upload_s = _busy(uploads)
        stats.kernel_s = _busy([e for es in kernels for e in es])
        stats.download_s = _busy([e for es in downloads for e in es])
        stats.wall_s = (
            max(e.profile.end for e in every) - min(e.profile.start for e in every)
        ) * 1e-9
    return stats


def _busy(events: list) -> float:
    """Seconds the events' commands ran, summed."""
    return sum(e.profile.end - e.profile.start for e in events) * 1e-9


def _note(log: list | None, kind: str, j: int, k: int, events, after: list) -> None:
    if log is not None:
        log.append((kind, j, k, events if isinstance(events, list) else [events], list(after)))


def with_device_format(engine, name: str, dtype: np.dtype, value_range: tuple[float, float]):
    """`engine` set to send bricks in device format `name` (checked now, before any work).

    ``auto`` keeps the engine as it is (with any format it was made with); another format needs
    an engine that copies bricks to a device (the OpenCL one).
    """
    check_format_name(name)
    if name == "auto":
        return engine
    if not hasattr(engine, "with_options"):
        label = getattr(engine, "name", type(engine).__name__)
        raise InvalidParameterError(
            f"--device-format {name} applies to the opencl engine; the {label} engine reads "
            "the data as stored (use --device-format auto)"
        )
    resolve_format(name, dtype, value_range)
    return engine.with_options(device_format=name)


def check_device_format(
    name: str, engine: str, dtype: np.dtype, value_range: tuple[float, float]
) -> DeviceFormat:
    """Check device format `name` for an engine by name and the data (before any work)."""
    check_format_name(name)
    if name != "auto" and engine != "opencl":
        raise InvalidParameterError(
            f"--device-format {name} applies to the opencl engine; the {engine} engine reads "
            "the data as stored (use --device-format auto)"
        )
    return resolve_format(name, dtype, value_range)
