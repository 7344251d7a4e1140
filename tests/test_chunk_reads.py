"""Direct chunk reads (`chronocl.data.chunk_reads`) against zarr's own read of the same array.

Rows read directly equal zarr's read for every layout the direct path takes (bytes, zstd or
none, with or without crc32c; chunks of any number of rows; contiguous and strided
destinations, aligned and unaligned row ranges; one step's rows, and bricks of several steps).
Damage never reads as data: a flipped byte, a truncated file and a frame of the wrong size all
end in StoreCorruptError naming the chunk, and a layout the direct path does not take
(sharding, chunked y-x planes) reads through zarr.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import zarr
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from zarr.codecs import BytesCodec, Crc32cCodec, ZstdCodec

import chronocl
from chronocl.core.errors import StoreCorruptError
from chronocl.data.chunk_reads import DirectChunks, read_rows, read_steps
from chronocl.data.integrity import CheckedStore
from chronocl.data.series import write_series

from .strategies import examples

CODECS = {
    "zstd+crc": [BytesCodec(), ZstdCodec(level=1), Crc32cCodec()],
    "zstd": [BytesCodec(), ZstdCodec(level=1)],
    "raw+crc": [BytesCodec(), Crc32cCodec()],
    "raw": [BytesCodec()],
}


def _bare(path: Path, values: np.ndarray, rows: int, codecs: str, **kw) -> zarr.Array:
    """A bare zarr v3 array of `values`, chunked (1, rows, Y, X), reopened as chronocl opens
    it (through its checked store)."""
    arr = zarr.create_array(
        store=str(path),
        shape=values.shape,
        chunks=kw.pop("chunks", (1, rows, *values.shape[2:])),
        dtype=values.dtype,
        serializer=CODECS[codecs][0],
        compressors=CODECS[codecs][1:],
        **kw,
    )
    arr[...] = values
    return zarr.open_array(store=CheckedStore(path, arrays=("",)), mode="r")


@settings(
    max_examples=examples(25),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    shape=st.tuples(st.integers(1, 3), st.integers(1, 13), st.integers(1, 9), st.integers(1, 11)),
    rows=st.integers(1, 6),
    codecs=st.sampled_from(sorted(CODECS)),
    dtype=st.sampled_from(["float32", "uint8", "int16", "float64"]),
    data=st.data(),
)
def test_direct_rows_equal_zarrs(tmp_path_factory, shape, rows, codecs, dtype, data):
    values = np.random.default_rng(sum(shape) + rows).normal(0, 50, shape).astype(dtype)
    arr = _bare(tmp_path_factory.mktemp("a") / "a.zarr", values, rows, codecs)
    assert DirectChunks.of(arr) is not None
    step = data.draw(st.integers(0, shape[0] - 1))
    z0 = data.draw(st.integers(0, shape[1] - 1))
    z1 = data.draw(st.integers(z0 + 1, shape[1]))
    strided = data.draw(st.booleans())
    # A strided destination: the rows of one slot in a (Z, S, Y, X) block, as the window's.
    block = np.full((shape[1], 3, *shape[2:]), 7, dtype)
    out = block[z0:z1, 1] if strided else np.full((z1 - z0, *shape[2:]), 7, dtype)
    read_rows(None, arr, step, z0, z1, out)
    np.testing.assert_array_equal(out, values[step, z0:z1])
    if strided:  # nothing outside the slot's rows was written
        assert (block[:, 0] == 7).all() and (block[:, 2] == 7).all()
    # A brick of several steps (the integrations' reads), its chunks decoded side by side.
    steps = data.draw(st.lists(st.integers(0, shape[0] - 1), min_size=1, max_size=4))
    brick = np.full((z1 - z0, len(steps), *shape[2:]), 7, dtype)
    assert read_steps(None, arr, steps, z0, z1, brick)
    np.testing.assert_array_equal(brick, values[steps, z0:z1].transpose(1, 0, 2, 3))


@pytest.fixture
def store(tmp_path) -> Path:
    path = tmp_path / "s.zarr"
    values = np.random.default_rng(3).random((4, 9, 6, 5), np.float32)
    # 3 rows a chunk, crc32c
    write_series(
        path, values, n_steps=4, volume_shape=(9, 6, 5), dtype="float32", chunk_bytes=3 * 6 * 5 * 4
    )
    return path


def test_a_chronocl_store_is_read_directly(store):
    series = chronocl.open(store)
    direct = DirectChunks.of(series.zarr_array)
    assert direct is not None and direct.crc and direct.zstd and direct.rows == 3
    out = np.empty((3, 6, 5), np.float32)
    assert direct.read_chunk(2, 1, out)  # taken, not handed to zarr
    np.testing.assert_array_equal(out, series.zarr_array[2, 3:6])


def _damage(store: Path, how: str) -> None:
    chunk = store / "data" / "c" / "2" / "1" / "0" / "0"
    raw = bytearray(chunk.read_bytes())
    if how == "flip":
        raw[len(raw) // 2] ^= 0x40
    elif how == "truncate":
        raw = raw[: len(raw) // 2]
    else:  # a sound frame with a valid checksum, of fewer rows than the chunk holds
        import google_crc32c
        import numcodecs

        frame = numcodecs.Zstd(level=1).encode(np.zeros((2, 6, 5), np.float32))
        raw = bytearray(frame + google_crc32c.value(frame).to_bytes(4, "little"))
    chunk.write_bytes(bytes(raw))


@pytest.mark.parametrize("how", ["flip", "truncate", "short frame"])
def test_a_damaged_chunk_is_reported_not_read(store, how):
    _damage(store, how)
    series = chronocl.open(store)
    out = np.full((9, 6, 5), -1, np.float32)
    with pytest.raises(StoreCorruptError, match="c/2/1/0/0"):
        series.read_rows(2, 0, 9, out)
    series.read_rows(1, 0, 9, out)  # the other steps still read
    np.testing.assert_array_equal(out, series.zarr_array[1])
    with pytest.raises(StoreCorruptError, match="c/2/1/0/0"):  # in a brick too
        series.read_brick([1, 2, 3], 2, 7)


def test_a_missing_chunk_is_reported(store):
    (store / "data" / "c" / "2" / "1" / "0" / "0").unlink()
    series = chronocl.open(store)
    with pytest.raises(StoreCorruptError, match="step 2"):
        series.read_rows(2, 0, 9, np.empty((9, 6, 5), np.float32))


@pytest.mark.parametrize(
    "kw",
    [{"chunks": (1, 2, 3, 5)}, {"shards": (1, 4, 6, 5), "chunks": (1, 2, 6, 5)}],
    ids=["chunked planes", "sharded"],
)
def test_other_layouts_read_through_zarr(tmp_path, kw):
    values = np.random.default_rng(5).random((2, 8, 6, 5), np.float32)
    arr = _bare(tmp_path / "a.zarr", values, 2, "zstd+crc", **kw)
    assert DirectChunks.of(arr) is None
    out = np.empty((8, 6, 5), np.float32)
    read_rows(None, arr, 1, 0, 8, out)
    np.testing.assert_array_equal(out, values[1])


def test_rows_of_another_dtype_are_converted_not_reinterpreted(tmp_path):
    values = np.arange(2 * 4 * 3 * 5, dtype=np.uint16).reshape(2, 4, 3, 5) * 7
    arr = _bare(tmp_path / "a.zarr", values, 2, "zstd+crc")
    for dtype in (np.float32, np.float64, np.int32):
        out = np.empty((2, 3, 5), dtype)  # one whole chunk's rows
        read_rows(None, arr, 1, 2, 4, out)
        np.testing.assert_array_equal(out, values[1, 2:4].astype(dtype))
