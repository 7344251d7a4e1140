"""TimeSeries over zarr (v3 written, v2 read), from_array, and Chronovolume save/load."""

from __future__ import annotations

import dask.array as da
import numpy as np
import pytest
import zarr
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl import modes
from chronocl.core.errors import InputNotFoundError, OutputExistsError, StoreFormatError
from chronocl.data.series import write_series
from chronocl.data.store_reads import step_runs

from .strategies import examples


def test_from_array_numpy_and_dask_are_lazy_and_equal(tmp_path):
    data = np.random.default_rng(0).random((4, 3, 5, 6)).astype(np.float32)
    a = chronocl.TimeSeries.from_array(data, spacing=(2, 1, 1), times=[0, 10, 20, 30])
    b = chronocl.TimeSeries.from_array(da.from_array(data, chunks=(1, 3, 5, 6)))
    for s in (a, b):
        assert isinstance(s.data, da.Array)
        assert s.vmin == pytest.approx(data.min()) and s.vmax == pytest.approx(data.max())
        np.testing.assert_array_equal(s.read([1, 3], 1, 2), data[[1, 3], 1:2])
    assert a.times == (0, 10, 20, 30) and a.spacing == (2.0, 1.0, 1.0)
    u = a.normalized([0])
    assert u.dtype == np.float32 and u.min() >= 0.0 and u.max() <= 1.0


def test_save_and_open_round_trip(tmp_path):
    data = np.random.default_rng(0).random((3, 4, 5, 6)).astype(np.float32)
    a = chronocl.TimeSeries.from_array(data, spacing=(3, 2, 1), times=["a", "b", "c"], source="x")
    a.save(tmp_path / "s.zarr")
    s = chronocl.open(tmp_path / "s.zarr")
    np.testing.assert_array_equal(s.data.compute(), data)
    assert (s.spacing, s.times, s.source) == ((3, 2, 1), ("a", "b", "c"), "x")
    summary = s.describe()
    assert summary["shape (T, Z, Y, X)"] == [3, 4, 5, 6]
    assert summary["spacing (x, y, z)"] == [3, 2, 1]
    assert "size on disk" in summary
    with pytest.raises(OutputExistsError):
        a.save(tmp_path / "s.zarr")


def test_open_zarr_v2_array_computes_statistics(tmp_path):
    data = np.arange(2 * 3 * 4 * 5, dtype=np.uint16).reshape(2, 3, 4, 5)
    z = zarr.open_array(
        store=str(tmp_path / "v2.zarr"),
        mode="w",
        shape=data.shape,
        dtype=data.dtype,
        chunks=(1, 3, 4, 5),
        zarr_format=2,
    )
    z[...] = data
    s = chronocl.open(tmp_path / "v2.zarr")
    assert (s.vmin, s.vmax) == (0, data.max())
    np.testing.assert_allclose(s.stats.step_mean, data.mean(axis=(1, 2, 3)))
    np.testing.assert_array_equal(s.read([1]), data[[1]])


def test_open_errors(tmp_path):
    with pytest.raises(InputNotFoundError, match="does not exist"):
        chronocl.open(tmp_path / "missing.zarr")
    (tmp_path / "folder").mkdir()
    with pytest.raises(StoreFormatError, match="not a zarr store"):
        chronocl.open(tmp_path / "folder")
    zarr.open_group(store=str(tmp_path / "g.zarr"), mode="w")
    with pytest.raises(StoreFormatError, match="no array 'data'"):
        chronocl.open(tmp_path / "g.zarr")
    zarr.open_array(store=str(tmp_path / "3d.zarr"), mode="w", shape=(2, 3, 4), dtype="f4")
    with pytest.raises(chronocl.ChronoclError, match="4D"):
        chronocl.open(tmp_path / "3d.zarr")


@pytest.mark.parametrize("mode", modes.names())
def test_chronovolume_round_trip(tmp_path, mode):
    data = np.random.default_rng(1).random((6, 3, 4, 5)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data, spacing=(2, 1, 1), source="rand")
    cv = chronocl.integrate(
        series, "1:6:2", mode, time_tf="warm-cool", enhance="edge", order="backward"
    )
    cv.save(tmp_path / "cv.zarr")
    back = chronocl.Chronovolume.load(tmp_path / "cv.zarr")
    np.testing.assert_array_equal(back.rgba, cv.rgba)
    assert back.rgba.dtype == np.float32 and back.shape == (3, 4, 5)
    if modes.get(mode).has_t_index:
        np.testing.assert_array_equal(back.t_index, cv.t_index)
        assert set(np.unique(back.t_index)) <= {-1, 1, 3, 5}
    else:
        assert back.t_index is None
    assert back.spec == cv.spec and back.steps == (1, 3, 5)
    assert back.metadata["dataset"] == "rand" and back.spacing == (2, 1, 1)
    with pytest.raises(StoreFormatError, match="not a chronovolume"):
        chronocl.Chronovolume.load(series.save(tmp_path / "s.zarr").path)
    with pytest.raises(StoreFormatError, match="is it a chronovolume"):
        chronocl.open(tmp_path / "cv.zarr")


@pytest.fixture(scope="module")
def chunked_store(tmp_path_factory):
    """9 steps of 11 x 3 x 5, stored 4 rows per chunk (the last chunk partial)."""
    data = np.random.default_rng(5).random((9, 11, 3, 5), dtype=np.float32)
    path = tmp_path_factory.mktemp("chunked") / "s.zarr"
    series = write_series(
        path,
        iter(data),
        n_steps=9,
        volume_shape=data.shape[1:],
        dtype="float32",
        chunk_bytes=4 * 3 * 5 * 4,
    )
    assert series.z_chunk == 4
    return series, data


@settings(max_examples=examples(60))
@given(
    steps=st.lists(st.integers(0, 8), min_size=1, max_size=12),
    rows=st.tuples(st.integers(0, 10), st.integers(1, 11)).filter(lambda r: r[0] < r[1]),
    most=st.integers(1, 5),
    given_out=st.booleans(),
)
def test_read_brick_decodes_runs_of_steps_into_the_brick(
    chunked_store, steps, rows, most, given_out
):
    """Whatever the steps (repeated, descending, strided) and rows, the brick equals the
    stored values step by step, read into a given buffer or a new one."""
    series, data = chunked_store
    z0, z1 = rows
    expected = np.stack([data[s, z0:z1] for s in steps], axis=1)
    out = np.full(expected.shape, np.nan, np.float32) if given_out else None
    brick = series.read_brick(steps, z0, z1, out=out, per_call=most)
    assert out is None or brick is out
    np.testing.assert_array_equal(brick, expected)


@given(steps=st.lists(st.integers(0, 30), max_size=20), most=st.integers(1, 6))
def test_step_runs_cover_the_steps_in_order(steps, most):
    runs = step_runs(steps, most)
    assert [i for i0, i1, _ in runs for i in range(i0, i1)] == list(range(len(steps)))
    for i0, i1, run in runs:
        assert 1 <= i1 - i0 <= most
        assert list(range(run.start, run.stop, run.step)) == list(steps[i0:i1])
