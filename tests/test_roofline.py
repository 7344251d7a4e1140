"""The read roofline's one bound (`chronocl.engine.roofline.bound_of`) and its readers."""

from __future__ import annotations

import numpy as np

from chronocl.engine.device import get_context
from chronocl.engine.roofline import bound_of, memory_read_fn, padded, read_fns


def test_the_bound_is_the_fastest_host_read_or_a_slower_copy_to_the_device():
    # A device reading host memory: whichever reader was faster that run is the memory's speed
    assert bound_of({"read-memory": 8.0, "read-opencl": 11.0}) == ("read-memory", 11.0)
    assert bound_of({"read-memory": 12.0, "read-opencl": 9.0}) == ("read-memory", 12.0)
    # A GPU: its read kernel reads device memory and bounds nothing; the copy does when slower
    gpu = {"read-memory": 12.0, "read-opencl": 2000.0, "copy-to-device": 25.0}
    assert bound_of(gpu) == ("read-memory", 12.0)
    assert bound_of({**gpu, "copy-to-device": 6.0}) == ("copy-to-device", 6.0)
    # A window resident on the GPU (a TF edit's re-integration) copies no step: the device's
    # read of it bounds, where it was measured (the brick fits the device); else as above
    assert bound_of({**gpu, "read-device": 900.0}, resident=True) == ("read-device", 900.0)
    assert bound_of(gpu, resident=True) == ("read-memory", 12.0)
    assert bound_of({"read-memory": 8.0, "read-opencl": 11.0}, resident=True) == (
        "read-memory",
        11.0,
    )


def test_the_copy_to_the_device_uploads_the_bricks_bytes_from_pinned_staging_in_chunks():
    """The GPU's copy bound is timed as the engine uploads (pinned staging, two buffers in
    turn, chunks of `chunk_bytes`), not as one pageable copy; forced here on the CPU device,
    with chunks of a third of the brick: each device buffer holds the chunk staged for it.
    The read of the brick resident on the device sums every voxel's steps."""
    import pyopencl as cl

    dc = get_context(None)
    brick = padded(np.random.default_rng(4).random((5, 3, 4, 19), dtype=np.float32))
    size = brick.nbytes // 3 + 1
    fns = read_fns(dc, brick, copy=True, chunk_bytes=size)
    fns["read-device"]()
    np.testing.assert_allclose(fns["read-device"].sums, brick.sum(axis=1), rtol=1e-6)
    copy = fns["copy-to-device"]
    assert len(copy.staged) == len(copy.device) == 2
    copy()
    data = brick.reshape(-1).view(np.uint8)
    for k, buf in enumerate(copy.device):
        back = np.empty(size, np.uint8)
        cl.enqueue_copy(dc.queue, back, buf)
        part = data[k * size : (k + 1) * size]
        np.testing.assert_array_equal(back[: part.size], part)


def test_the_memory_read_reads_every_byte_of_an_odd_brick():
    rng = np.random.default_rng(2)
    brick = padded(rng.random((37, 3, 7, 21), dtype=np.float32))
    assert brick.shape[3] % 16 == 0 and (brick[..., 21:] == 0).all()
    brick[29, 2, 6, 20] = 7.0  # in the last piece of z rows, the last row, the last voxel
    assert np.max(memory_read_fn(brick, threads=4)()) == 7.0
    assert set(read_fns(get_context(None), brick)) >= {"read-memory", "read-opencl"}


def test_the_opencl_read_takes_a_brick_over_the_largest_allocation_in_chunks(
    monkeypatch, buffer_sizes
):
    """A brick over the device's largest allocation (a 10 x 512^3 float32 brick is 5.4 GB) is
    read a few z rows at a time (`chronocl.engine.buffers.max_alloc`, lowered here by
    CHRONOCL_MAX_ALLOC to two z rows a buffer): every voxel's sum over its steps comes out."""
    from chronocl.engine import buffers

    dc = get_context(None)
    rng = np.random.default_rng(3)
    brick = padded(rng.random((7, 3, 5, 21), dtype=np.float32))
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, str(2 * brick[:1].nbytes))
    read = read_fns(dc, brick)["read-opencl"]
    read()
    assert buffer_sizes and max(buffer_sizes) <= 2 * brick[:1].nbytes  # in chunks of two rows
    np.testing.assert_allclose(read.sums, brick.sum(axis=1), rtol=1e-6)


def test_the_read_roofline_measures_without_deadlocking_on_the_device_lock():
    """read_roofline held the device's lock around its readers, which take it themselves
    (`DeviceWork`; a non-reentrant lock): it hung for ever. Run in a thread, with a limit."""
    import threading

    from chronocl.engine.roofline import read_roofline

    brick = np.random.default_rng(4).random((4, 2, 8, 16), dtype=np.float32)
    result: dict = {}
    thread = threading.Thread(
        target=lambda: result.update(read_roofline(brick, repeats=1)), daemon=True
    )
    thread.start()
    thread.join(timeout=120)
    assert not thread.is_alive(), "read_roofline deadlocked on the device's lock"
    assert result["opencl_read_gb_s"] > 0
