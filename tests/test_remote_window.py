"""Fetch what changed only: the window manager over HTTP, its requests counted by the server.

A slide by one step reads the entering step's chunks and nothing else (no metadata, no chunk
of a step already resident); with prefetch on, the slide itself reads nothing and the next
step's chunks are fetched ahead.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

import chronocl
from chronocl import WindowManager
from chronocl.data.series import write_series

from .remote_servers import StoreServer

pytest.importorskip("aiohttp")

SHAPE = (8, 16, 16, 32)  # 4 rows of 16 x 32 float32 a chunk: 4 chunks a step
ROWS = 4


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    root = tmp_path_factory.mktemp("window")
    data = np.random.default_rng(5).random(SHAPE, dtype=np.float32)
    write_series(
        root / "w.zarr",
        list(data),
        n_steps=SHAPE[0],
        volume_shape=SHAPE[1:],
        dtype=np.float32,
        chunk_bytes=ROWS * SHAPE[2] * SHAPE[3] * 4,
    )
    with StoreServer(root) as srv:
        yield srv


def step_chunks(t: int) -> dict[str, int]:
    return {f"w.zarr/data/c/{t}/{z}/0/0": 1 for z in range(SHAPE[1] // ROWS)}


def settle(wm: WindowManager, step: int) -> None:
    """Wait until `step`, read ahead in the background, is resident."""
    deadline = time.monotonic() + 30
    while step not in wm.resident():
        assert time.monotonic() < deadline, f"step {step} was never prefetched"
        time.sleep(0.01)


def test_a_slide_fetches_only_the_entering_step(server):
    series = chronocl.open(server.url("w.zarr"))
    assert series.z_chunk == ROWS
    with WindowManager(series, memory="1MB", prefetch=0) as wm:
        wm.get(range(0, 4), direction=+1)
        server.requests.clear()
        arrays = wm.get(range(1, 5), direction=+1)
        assert dict(server.requests) == step_chunks(4)
        np.testing.assert_array_equal(arrays[-1], series.read([4])[0])
        server.requests.clear()
        wm.get(range(0, 4), direction=-1)  # back: step 0 may have been kept, else re-read
        assert dict(server.requests) in ({}, step_chunks(0))


def test_with_prefetch_the_slide_reads_nothing_and_the_next_step_ahead(server):
    series = chronocl.open(server.url("w.zarr"))
    with WindowManager(series, memory="1MB", prefetch=1) as wm:
        wm.get(range(0, 4), direction=+1)
        settle(wm, 4)
        server.requests.clear()
        wm.get(range(1, 5), direction=+1)
        assert not server.requests.keys() - step_chunks(5).keys()  # at most the one ahead
        settle(wm, 5)
        assert dict(server.requests) == step_chunks(5)
        assert all(n == 1 for n in wm.reads.values())
