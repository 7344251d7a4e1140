"""Host-to-device transfers of bricks: chunked uploads that overlap the kernels.

On a GPU the PCIe transfer of a brick, not the kernel, bounds an integration. Two things cut
it (docs/engine.md, "Transfers and device formats"):

* **Device formats** (`chronocl.engine.device_formats`): a brick may travel narrower than it
  is stored (float16, or uint8 / uint16 quantised over the value range).
* **Overlap** (`run_chunks`): a brick is cut into chunks of output rows (with their gradient
  halo); chunk i+1 is encoded into a pinned host staging buffer (``CL_MEM_ALLOC_HOST_PTR``,
  mapped) and uploaded on one queue while the kernel of chunk i runs on a second and the result
  of chunk i-1 is read back on a third. Two device buffers of each kind are used in turn; events
  order the reuse: an upload into a buffer waits for the kernel that last read it, a kernel
  waits for its upload and for the read-back of the output buffer it writes.

Timings come from OpenCL profiling events (`TransferStats`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from chronocl.engine.device_formats import DeviceFormat

MIN_CHUNK, MAX_CHUNK = 4 << 20, 64 << 20  # bytes of one transfer chunk (auto sizing)


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
        return {**asdict(self), "transfer_s": self.transfer_s, "overlap": self.overlap}


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
    return _cut(z0, z1, per, halo, nzb)


def fit(
    chunks: Sequence[Chunk], nzb: int, halo: int, in_row: int, out_row: int, limit: int
) -> list[Chunk]:
    """`chunks` cut further where one's brick rows (`in_row` bytes each, halo included; 0:
    spans the caller has fitted) or output rows (`out_row` bytes each) are over `limit` bytes,
    the device's largest buffer (`chronocl.engine.buffers.max_alloc`). Chunks that fit stay."""
    from chronocl.engine.buffers import DeviceLimitError

    most = limit // out_row
    if in_row:
        most = min(most, limit // in_row - 2 * halo)
    if most < 1:
        raise DeviceLimitError(
            f"one row of a brick ({max(in_row, out_row)} bytes) is over the device's largest "
            f"buffer ({limit} bytes): use smaller steps, or a device with more memory"
        )
    out = []
    for c in chunks:
        fits = c.b - c.a <= most and (c.r1 - c.r0) * in_row <= limit
        out += [c] if fits else _cut(c.a, c.b, most, halo, nzb)
    return out


def _cut(a0: int, a1: int, per: int, halo: int, nzb: int) -> list[Chunk]:
    """Output rows [a0, a1) in chunks of `per`, each with up to `halo` brick rows either side."""
    bounds = [(a, min(a + per, a1)) for a in range(a0, a1, per)]
    return [Chunk(a, b, max(0, a - halo), min(nzb, b + halo)) for a, b in bounds]


@dataclass
class Streams:
    """The queues of overlapped transfers on one device (upload, compute, read-back) and the
    pinned staging and device buffers they reuse from brick to brick."""

    upload: object
    compute: object
    download: object
    profiling: bool
    buffers: dict = field(default_factory=dict)

    def buffer(self, dc, key: str, nbytes: int, access: str):
        """A cached device buffer of at least `nbytes` (grown, never shrunk)."""
        from chronocl.engine.buffers import buffer

        held = self.buffers.get(key)
        if held is None or held.size < nbytes:
            self.buffers.pop(key, None)
            held = buffer(dc, nbytes=nbytes, access=access)
            self.buffers[key] = held
        return held

    def staging(self, dc, key: str, nbytes: int) -> np.ndarray:
        """A pinned host buffer (ALLOC_HOST_PTR) of at least `nbytes`, mapped once and kept
        mapped: a byte array the host writes a chunk into before it is uploaded."""
        import pyopencl as cl

        from chronocl.engine.buffers import buffer

        held = self.buffers.get(key)
        if held is None or held.nbytes < nbytes:
            self.buffers.pop(key, None)
            if held is not None:
                held.base.release(self.upload)
            buf = buffer(dc, nbytes=nbytes, pinned=True)
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

    def clear(self) -> None:
        """Release the reused buffers (unmapping the staging ones) once the queues' work is
        done: the next brick makes them again (tests/device_faults.py fails each call of
        a frame's work, these buffers' making included)."""
        for queue in (self.upload, self.compute, self.download):
            queue.finish()  # nothing enqueued may still use them
        held, self.buffers = self.buffers, {}
        for buf in held.values():
            if isinstance(buf, np.ndarray):  # a mapped staging buffer
                buf.base.release(self.upload)
            else:
                buf.release()
        self.upload.finish()


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
    dc,
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

    up, comp, down = (
        (streams.upload, streams.compute, streams.download) if overlap else (streams.compute,) * 3
    )
    row_in = int(np.prod(brick.shape[1:])) * fmt.dtype.itemsize
    rows_out = [int(np.prod(o.shape[1:])) * o.dtype.itemsize for o in outputs]
    max_in = max(c.rows for c in chunks) * row_in
    max_out = max(c.b - c.a for c in chunks)
    slots = 2 if len(chunks) > 1 else 1
    staging = [streams.staging(dc, f"stage{k}", max_in) for k in range(slots)]
    dev_in = [streams.buffer(dc, f"in{k}", max_in, "r") for k in range(slots)]
    dev_out = [
        [streams.buffer(dc, f"out{k}.{i}", max_out * rb, "w") for i, rb in enumerate(rows_out)]
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
