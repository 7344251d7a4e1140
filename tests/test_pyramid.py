"""Coarse levels (chronocl.data.pyramid): the pooling rule against a plain numpy oracle, stored
levels against in-memory ones, the level series, damaged levels, an interrupted build, the CLI.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from chronocl.core.errors import (
    InvalidDataError,
    InvalidParameterError,
    StoreCorruptError,
    StoreFormatError,
)
from chronocl.data.level_writer import add_levels
from chronocl.data.pyramid import POOLS, downsample, level_shapes
from chronocl.data.series import open_series, write_series
from chronocl.data.timeseries import TimeSeries
from chronocl.data.verify import verify

from .strategies import examples
from .test_cli import cli

DTYPES = ("uint8", "uint16", "int16", "float32", "float64")
SHAPE = (3, 130, 9, 70)  # T, Z, Y, X: levels (65, 5, 35) and (33, 3, 18), odd edges on the way


def oracle(a: np.ndarray, pool: str) -> np.ndarray:
    """2x2x2 pooling written plainly: every offset of a block, partial blocks at the edges."""
    out_shape = tuple(-(-n // 2) for n in a.shape)
    total = np.zeros(out_shape)
    count = np.zeros(out_shape)
    best = None
    for dz, dy, dx in itertools.product(range(2), repeat=3):
        part = a[dz::2, dy::2, dx::2].astype(np.float64)
        region = tuple(slice(0, n) for n in part.shape)
        total[region] += part
        count[region] += 1
        if best is None:
            best = part.copy()  # offset (0, 0, 0) covers every block
        elif pool == "max":
            best[region] = np.maximum(best[region], part)
        elif pool == "min":
            best[region] = np.minimum(best[region], part)
    if pool != "mean":
        return best.astype(a.dtype)
    mean = total / count
    if a.dtype.kind in "iu":
        mean = np.rint(mean)
    return mean.astype(a.dtype)


def assert_pooled(got: np.ndarray, previous: np.ndarray, pool: str) -> None:
    want = oracle(previous, pool)
    assert got.dtype == previous.dtype and got.shape == want.shape
    if pool == "mean" and got.dtype.kind == "f":  # float64 sums in another order
        rtol = 1e-6 if got.dtype == np.float32 else 1e-12
        scale = float(np.abs(previous).max())  # sums that cancel lose digits of the inputs
        np.testing.assert_allclose(got, want, rtol=rtol, atol=rtol * scale)
    else:
        np.testing.assert_array_equal(got, want)


def values(shape: tuple[int, ...], dtype: str, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    dt = np.dtype(dtype)
    if dt.kind == "f":
        return rng.normal(0, 100, shape).astype(dt)
    info = np.iinfo(dt)
    return rng.integers(info.min, info.max, shape, endpoint=True).astype(dt)


def store(path: Path, data: np.ndarray, **options) -> TimeSeries:
    return write_series(
        path,
        iter(data),
        n_steps=data.shape[0],
        volume_shape=data.shape[1:],
        dtype=data.dtype,
        spacing=(2.0, 1.0, 0.5),
        **options,
    )


# -- the rule ---------------------------------------------------------------------------------
def test_level_shapes():
    assert level_shapes((256, 256, 256)) == [(128, 128, 128), (64, 64, 64)]
    assert level_shapes((512, 512, 512)) == [(256,) * 3, (128,) * 3, (64,) * 3]
    assert level_shapes((64, 64, 64)) == []
    assert level_shapes((100, 40, 40)) == [(50, 20, 20)]
    assert level_shapes((1, 1, 130)) == [(1, 1, 65), (1, 1, 33)]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize(
    "shape", [(7, 5, 9), (1, 6, 3), (2, 2, 2), (1, 1, 1), (3, 1, 4), (4, 6, 8)]
)
def test_downsample_matches_the_oracle(dtype, shape):
    a = values(shape, dtype)
    for pool in POOLS:
        assert_pooled(downsample(a, pool), a, pool)


@settings(max_examples=examples(20))
@given(
    shape=st.tuples(*[st.integers(1, 11)] * 3),
    dtype=st.sampled_from(DTYPES),
    seed=st.integers(0, 2**16),
)
def test_downsample_property(shape, dtype, seed):
    a = values(shape, dtype, seed)
    for pool in POOLS:
        assert_pooled(downsample(a, pool), a, pool)


@settings(max_examples=examples(15))
@given(half=st.tuples(*[st.integers(1, 6)] * 3), seed=st.integers(0, 2**16))
def test_uint8_fast_path_property(half, seed):
    """uint8 steps with even sides take a faster path; it gives the oracle's values, and so
    does a non-contiguous view of one (the general path)."""
    a = values(tuple(2 * n for n in half), "uint8", seed)
    for pool in POOLS:
        assert_pooled(downsample(a, pool), a, pool)
        view = a.transpose(0, 2, 1)
        assert_pooled(downsample(view, pool), view, pool)
        out = np.empty(tuple(half), np.uint8)
        assert downsample(a, pool, out) is out
        assert_pooled(out, a, pool)


def test_mean_rounds_half_to_even():
    a = np.zeros((2, 2, 2), np.uint8)
    a[0, 0, 0] = 4  # mean 0.5 -> 0
    assert downsample(a, "mean")[0, 0, 0] == 0
    a[0, 0, 0] = 12  # mean 1.5 -> 2
    assert downsample(a, "mean")[0, 0, 0] == 2
    b = np.full((2, 2, 2), -3, np.int16)
    b[0, 0, 0] = 1  # mean -2.5 -> -2
    assert downsample(b, "mean")[0, 0, 0] == -2


@pytest.mark.parametrize("dtype", DTYPES)
def test_every_stored_level_pools_the_previous_one(tmp_path, dtype):
    data = values(SHAPE, dtype)
    series = store(tmp_path / "s.zarr", data)
    assert series.n_levels == 3
    for pool in POOLS:
        previous = data
        for n in (1, 2):
            level = series.level(n, pool).read(range(SHAPE[0]))
            for t in range(SHAPE[0]):
                assert_pooled(level[t], previous[t], pool)
            previous = level


# -- writing level chunks ---------------------------------------------------------------------
def _chunk_files(root: Path) -> dict:
    return {
        str(f.relative_to(root)): hashlib.sha256(f.read_bytes()).hexdigest()
        for f in sorted(root.rglob("*"))
        if f.is_file() and f.name != "zarr.json"
    }


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("compressor", ["zstd", "none"])
@pytest.mark.parametrize("checksum", [True, False])
def test_level_chunks_written_directly_are_zarrs_own(tmp_path, dtype, compressor, checksum):
    """The direct writer's chunk files are byte for byte those zarr writes (edge chunks padded
    to full size included), and read back through zarr unchanged."""
    import zarr

    from chronocl.data.level_writer import (
        _write_step_chunks,
        _write_together,
        chunk_files,
        level_compressors,
    )
    from chronocl.data.writer import compressors

    data = values((2, 11, 6, 5), dtype, 4)
    arrays = []
    for name in ("zarr", "direct"):
        group = zarr.open_group(store=str(tmp_path / name), mode="w", zarr_format=3)
        arrays.append(
            group.create_array(
                "a",
                shape=data.shape,
                chunks=(1, 4, 6, 5),  # 11 planes: the last chunk is an edge chunk
                dtype=data.dtype,
                compressors=level_compressors(compressors(compressor, checksum)),
                config={"write_empty_chunks": True},
            )
        )
    files = chunk_files(arrays[1])
    assert files is not None
    for t in range(data.shape[0]):
        _write_together([(arrays[0], t, data[t])])
        _write_step_chunks(arrays[1], t, data[t], files)
    assert _chunk_files(tmp_path / "zarr") == _chunk_files(tmp_path / "direct")
    reread = zarr.open_array(store=str(tmp_path / "direct"), path="a", mode="r")[:]
    np.testing.assert_array_equal(reread, data)


@pytest.mark.parametrize("compressor", ["zstd", "blosc-lz4", "none"])
@pytest.mark.parametrize("checksum", [True, False])
def test_levels_in_a_local_store_are_written_as_files(tmp_path, compressor, checksum):
    """The level writer's own arrays in a local directory take the direct writer, read from the
    zarr v3 metadata of whichever zarr is installed (a zarr that spelled it otherwise would
    silently fall back to zarr's slower writes)."""
    import zarr

    from chronocl.data.level_writer import LevelWriter
    from chronocl.data.writer import compressors

    group = zarr.open_group(store=str(tmp_path / "l"), mode="w", zarr_format=3)
    codecs = compressors(compressor, checksum)
    writer = LevelWriter(group, (2, 130, 9, 70), "float32", codecs, chunk_bytes=2**20)
    assert writer.direct


def test_levels_in_a_store_zarr_writes_itself():
    """Arrays outside a local directory (here zarr's memory store) get their levels through
    zarr, with the same values."""
    import zarr

    from chronocl.data.level_writer import LevelWriter

    data = values((2, 130, 9, 70), "float32", 5)
    group = zarr.open_group(store=zarr.storage.MemoryStore(), mode="w", zarr_format=3)
    writer = LevelWriter(group, data.shape, data.dtype, None, chunk_bytes=2**20)
    assert not writer.direct
    for t in range(data.shape[0]):
        writer.add(t, data[t])
    writer.finish()
    for pool in POOLS:
        got = np.asarray(group["1"][pool][:])
        for t in range(data.shape[0]):
            assert_pooled(got[t], data[t], pool)
    with pytest.raises(InvalidDataError, match="expected 2"):
        writer.pool(5, data[0])


def test_a_reused_step_buffer_gives_each_steps_levels(tmp_path):
    """A reader that fills one buffer per step: the levels of a step are pooled before the
    buffer is handed back, while their chunks are written beside the next step."""
    data = values(SHAPE, "uint8", 6)
    buffer = np.empty(SHAPE[1:], data.dtype)

    def reused():
        for step in data:
            buffer[...] = step
            yield buffer

    series = write_series(
        tmp_path / "r.zarr",
        reused(),
        n_steps=SHAPE[0],
        volume_shape=SHAPE[1:],
        dtype=data.dtype,
    )
    for pool in POOLS:
        level = series.level(1, pool).read(range(SHAPE[0]))
        for t in range(SHAPE[0]):
            assert_pooled(level[t], data[t], pool)


# -- stored, added and in-memory levels agree ------------------------------------------------
def _levels(series: TimeSeries) -> dict:
    return {
        (n, pool): np.asarray(series.level(n, pool).data.compute())
        for n in range(1, series.n_levels)
        for pool in POOLS
    }


def test_write_store_add_levels_and_memory_agree(tmp_path):
    data = values(SHAPE, "uint16", 3)
    written = store(tmp_path / "a.zarr", data)
    bare = store(tmp_path / "b.zarr", data, levels=False)
    assert bare.n_levels == 1 and not (tmp_path / "b.zarr" / "levels").exists()
    summary = add_levels(tmp_path / "b.zarr")
    assert summary["status"] == "added"
    added = open_series(tmp_path / "b.zarr")
    memory = TimeSeries.from_array(data, spacing=(2.0, 1.0, 0.5))
    assert written.n_levels == added.n_levels == memory.n_levels == 3
    a, b, m = _levels(written), _levels(added), _levels(memory)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
        np.testing.assert_array_equal(a[key], m[key])
        assert written.level(*key).stats == added.level(*key).stats == memory.level(*key).stats
    attrs = [
        json.loads((tmp_path / name / "levels" / "zarr.json").read_text())["attributes"]
        for name in ("a.zarr", "b.zarr")
    ]
    assert attrs[0] == attrs[1]
    assert attrs[0]["chronocl"]["format"] == "chronocl.levels"
    assert attrs[0]["chronocl"]["levels"][0]["factor"] == [2.0, 9 / 5, 2.0]


def test_level_series(tmp_path):
    data = values(SHAPE, "float32", 5)
    series = store(tmp_path / "s.zarr", data)
    assert series.level(0) is series and series.level_index == 0
    extent = np.array(series.dims) * np.array(series.spacing)
    for n, pool in itertools.product((1, 2), POOLS):
        level = series.level(n, pool)
        assert level.level_index == n and level.volume_shape == level_shapes(SHAPE[1:])[n - 1]
        assert (level.vmin, level.vmax) == (series.vmin, series.vmax)
        np.testing.assert_allclose(np.array(level.dims) * level.spacing, extent)
        assert level.times == series.times and level.path == series.path
        assert level.source == series.source
        arr = np.asarray(level.data.compute())
        np.testing.assert_array_equal(level.read(range(SHAPE[0])), arr)
        np.testing.assert_array_equal(level.read([1], 3, 9)[0], arr[1, 3:9])
        assert level.stats.step_min == tuple(float(s.min()) for s in arr)
        assert level.stats.step_max == tuple(float(s.max()) for s in arr)
        means = [float(s.mean(dtype=np.float64)) for s in arr]
        np.testing.assert_allclose(level.stats.step_mean, means, rtol=1e-12)
        assert level.level(0) is series and level.n_levels == 3
    assert series.level(2, "max").stats.step_max == series.stats.step_max
    assert series.level(2, "min").stats.step_min == series.stats.step_min
    assert series.describe()["levels"] == "0..2 (70×9×130, 35×5×65, 18×3×33)"  # x×y×z
    assert verify(tmp_path / "s.zarr")["levels checked"] == "1..2 (mean, max, min)"


def test_small_series_have_no_levels(tmp_path):
    series = store(tmp_path / "s.zarr", values((2, 64, 8, 8), "uint8"))
    assert series.n_levels == 1 and not (tmp_path / "s.zarr" / "levels").exists()
    assert add_levels(tmp_path / "s.zarr")["status"].startswith("nothing to add")
    with pytest.raises(InvalidParameterError, match="level 1 is out of range"):
        series.level(1)


# -- bad input ----------------------------------------------------------------------------------
@pytest.fixture
def leveled(tmp_path) -> Path:
    store(tmp_path / "jet.zarr", values(SHAPE, "float32", 7))
    return tmp_path / "jet.zarr"


def test_level_out_of_range_and_unknown_pool(leveled):
    series = open_series(leveled)
    with pytest.raises(
        InvalidParameterError, match=r"level 5 is out of range: jet.zarr has levels 0\.\.2"
    ):
        series.level(5)
    with pytest.raises(InvalidParameterError, match="out of range"):
        series.level(-1)
    with pytest.raises(
        InvalidParameterError, match="unknown pool 'median'; choose one of mean, max, min"
    ):
        series.level(1, "median")
    memory = TimeSeries.from_array(values(SHAPE, "uint8"), source="mem")
    with pytest.raises(InvalidParameterError, match=r"mem has levels 0\.\.2"):
        memory.level(3)


def test_store_without_levels(tmp_path):
    store(tmp_path / "jet.zarr", values(SHAPE, "uint8"), levels=False)
    series = open_series(tmp_path / "jet.zarr")
    assert series.n_levels == 1
    assert "pyramid" in series.describe()["levels"] or series.describe()["levels"].startswith("0 ")
    with pytest.raises(
        StoreFormatError, match=r"jet\.zarr has no coarse levels; add them with 'chronocl pyramid"
    ):
        series.level(1)


def test_deleted_level_chunk_is_reported(leveled):
    chunk = leveled / "levels" / "1" / "max" / "c.1.0.0.0"
    assert chunk.is_file()
    chunk.unlink()
    level = open_series(leveled).level(1, "max")
    level.read([0])  # another step reads fine
    missing = r"levels/1/max/c\.1\.0\.0\.0 \(step 1\) is missing"
    with pytest.raises(StoreCorruptError, match=missing):
        level.read([1])
    with pytest.raises(StoreCorruptError):
        level.data[1].compute()
    with pytest.raises(StoreCorruptError):
        verify(leveled)


def test_changed_level_chunk_is_reported(leveled):
    chunk = leveled / "levels" / "2" / "mean" / "c.0.0.0.0"
    raw = bytearray(chunk.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    chunk.write_bytes(bytes(raw))
    with pytest.raises(StoreCorruptError, match="cannot be decoded"):
        open_series(leveled).level(2).read([0])


@pytest.mark.parametrize(
    "edit",
    [
        lambda d: d["attributes"].pop("chronocl"),
        lambda d: d["attributes"]["chronocl"]["levels"].pop(),
        lambda d: d["attributes"]["chronocl"].update(shape=[4, 130, 9, 70]),
        lambda d: d["attributes"]["chronocl"]["levels"][0]["stats"]["max"].update(step_min=[1]),
    ],
)
def test_damaged_levels_attribute_is_reported(leveled, edit):
    meta = leveled / "levels" / "zarr.json"
    doc = json.loads(meta.read_text())
    edit(doc)
    meta.write_text(json.dumps(doc))
    series = open_series(leveled)
    with pytest.raises(StoreCorruptError, match="--force"):
        series.level(1)
    with pytest.raises(StoreCorruptError):
        _ = series.n_levels


def test_unreadable_or_missing_levels_metadata(leveled):
    meta = leveled / "levels" / "zarr.json"
    meta.write_text("{not json")
    with pytest.raises(StoreCorruptError, match="cannot be read"):
        open_series(leveled).level(1)
    meta.unlink()
    with pytest.raises(StoreCorruptError, match="is missing"):
        open_series(leveled).level(1)


# -- add_levels and the CLI -------------------------------------------------------------------
def _digest(path: Path) -> dict[str, str]:
    """Hashes of the store's data and root metadata (what add_levels must not touch)."""
    files = [path / "zarr.json", *sorted((path / "data").rglob("*"))]
    return {
        str(f.relative_to(path)): hashlib.sha256(f.read_bytes()).hexdigest()
        for f in files
        if f.is_file()
    }


def test_pyramid_cli(tmp_path):
    data = values(SHAPE, "int16", 9)
    store(tmp_path / "s.zarr", data, levels=False)
    before = _digest(tmp_path / "s.zarr")
    first = cli("pyramid", str(tmp_path / "s.zarr"))
    assert first.returncode == 0, first.stderr
    assert "added" in first.stdout and "0..2" in first.stdout
    assert _digest(tmp_path / "s.zarr") == before
    assert open_series(tmp_path / "s.zarr").n_levels == 3
    again = cli("pyramid", str(tmp_path / "s.zarr"))
    assert again.returncode == 0 and "already present" in again.stdout
    assert add_levels(tmp_path / "s.zarr", force=True)["status"] == "rebuilt"
    assert sorted(os.listdir(tmp_path / "s.zarr")) == ["data", "levels", "zarr.json"]
    assert _digest(tmp_path / "s.zarr") == before
    missing = cli("pyramid", str(tmp_path / "nope.zarr"))
    lines = missing.stderr.strip().splitlines()
    assert missing.returncode == 2 and len(lines) == 1 and "does not exist" in lines[0]
    assert "Traceback" not in missing.stderr
    with pytest.raises(StoreFormatError, match="not a chronocl store"):
        add_levels(tmp_path)


def test_interrupted_build_leaves_no_levels_and_reruns(tmp_path):
    path = tmp_path / "big.zarr"
    t, shape = 48, (130, 130, 130)
    grid = sum(np.ogrid[: shape[0], : shape[1], : shape[2]])
    steps = [((grid + 7 * i) % 251).astype(np.uint8) for i in range(t)]
    write_series(path, iter(steps), n_steps=t, volume_shape=shape, dtype="uint8", levels=False)
    before = _digest(path)
    proc = subprocess.Popen(
        [sys.executable, "-m", "chronocl", "pyramid", str(path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 60
    partial = []
    while time.monotonic() < deadline and proc.poll() is None:
        partial = [p for p in path.iterdir() if p.name.startswith(".levels.partial-")]
        if partial and any((partial[0] / "1" / "mean").glob("c.*")):
            break
        time.sleep(0.005)
    assert proc.poll() is None, "the build finished before it could be interrupted"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert partial and not (path / "levels").exists()
    assert _digest(path) == before
    series = open_series(path)
    assert series.n_levels == 1  # the partial is never read as levels
    with pytest.raises(StoreFormatError):
        series.level(1)
    rerun = cli("pyramid", str(path))
    assert rerun.returncode == 0, rerun.stderr
    assert sorted(os.listdir(path)) == ["data", "levels", "zarr.json"]  # the stale one is gone
    assert _digest(path) == before
    series = open_series(path)
    memory = TimeSeries.from_array(np.stack(steps[:4]))
    for n, pool in itertools.product((1, 2), POOLS):
        np.testing.assert_array_equal(
            series.level(n, pool).read(range(4)), memory.level(n, pool).data.compute()
        )


@pytest.mark.parametrize("dtype", ["uint8", "int16", "float32"])
def test_step_statistics_from_the_pooling_equal_numpys(tmp_path, dtype):
    """With levels, a step's min, max and mean come from its pooling (level 1's min and max
    pools, the mean pool's sums): the same as numpy's, exactly for integers."""
    data = values((3, 130, 10, 72), dtype, 7)
    stats = store(tmp_path / "s.zarr", data).stats
    assert stats.step_min == tuple(float(s.min()) for s in data)
    assert stats.step_max == tuple(float(s.max()) for s in data)
    means = [float(s.mean(dtype=np.float64)) for s in data]
    if dtype == "float32":
        np.testing.assert_allclose(stats.step_mean, means, rtol=1e-12)
    else:
        assert stats.step_mean == tuple(means)
