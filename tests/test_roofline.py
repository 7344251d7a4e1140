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


def test_the_memory_read_reads_every_byte_of_an_odd_brick():
    rng = np.random.default_rng(2)
    brick = padded(rng.random((37, 3, 7, 21), dtype=np.float32))
    assert brick.shape[3] % 16 == 0 and (brick[..., 21:] == 0).all()
    brick[29, 2, 6, 20] = 7.0  # in the last piece of z rows, the last row, the last voxel
    assert np.max(memory_read_fn(brick, threads=4)()) == 7.0
    assert set(read_fns(get_context(None), brick)) >= {"read-memory", "read-opencl"}
