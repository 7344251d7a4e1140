"""NetCDF/HDF5 ingest: files written by xarray, netCDF4 and h5py -> store -> same values."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import ChronoclError, InputNotFoundError, InvalidDataError
from chronocl.data.formats.netcdf import ingest_netcdf

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")
h5py = pytest.importorskip("h5py")

T, Z, Y, X = 3, 5, 4, 6
TIMES = np.array(["2020-01-01T00", "2020-01-01T06", "2020-01-01T12"], dtype="datetime64[ns]")


def sample(dtype="float32") -> np.ndarray:
    return (np.random.default_rng(3).random((T, Z, Y, X)) * 100).astype(dtype)


def dataset(data: np.ndarray, **extra) -> xr.Dataset:
    coords = {
        "time": TIMES,
        "z": np.arange(Z) * 2.5,
        "y": np.array([0.0, 1.0, 2.0, 3.0]),  # uniform; non-uniform ones: tests/test_nonuniform.py
        "x": np.arange(X) * 0.5 + 10,
    }
    return xr.Dataset({"temp": (("time", "z", "y", "x"), data), **extra}, coords=coords)


def no_partial(folder) -> bool:
    return not [p for p in folder.iterdir() if ".partial-" in p.name]


def one_line_error(exc_info, kind=ChronoclError) -> str:
    assert isinstance(exc_info.value, kind)
    msg = str(exc_info.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("engine", ["h5netcdf", "netcdf4"])
def test_round_trip_spacing_and_times(tmp_path, engine):
    pytest.importorskip("netCDF4" if engine == "netcdf4" else "h5netcdf")
    data = sample()
    dataset(data).to_netcdf(tmp_path / "a.nc", engine=engine)
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr")
    reopened = chronocl.open(tmp_path / "s.zarr")
    for s in (series, reopened):
        assert s.shape == (T, Z, Y, X) and s.dtype == np.float32
        np.testing.assert_array_equal(s.read(range(T)), data)
        assert s.spacing == (0.5, 1.0, 2.5)  # (dx, dy, dz)
        assert s.times == ("2020-01-01T00:00:00.000000000", *s.times[1:])
        assert s.times[2].startswith("2020-01-01T12:00")
        assert s.vmin == data.min() and s.vmax == data.max()
        assert "a.nc:temp" in s.source


def test_netcdf3_and_numeric_times(tmp_path):
    pytest.importorskip("netCDF4")
    data = sample("int16")
    ds = dataset(data).assign_coords(time=[0.0, 0.5, 1.0])
    ds.to_netcdf(tmp_path / "a.nc", engine="netcdf4", format="NETCDF3_CLASSIC")
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr")
    assert series.dtype == np.int16 and series.times == (0.0, 0.5, 1.0)
    np.testing.assert_array_equal(series.read(range(T)), data)


def test_plain_hdf5_is_taken_in_file_order(tmp_path):
    data = sample("uint16")
    with h5py.File(tmp_path / "a.h5", "w") as f:
        f["density"] = data
        f["mask"] = np.zeros((Y, X))
    series = ingest_netcdf(tmp_path / "a.h5", tmp_path / "s.zarr")
    assert series.dtype == np.uint16 and series.spacing == (1.0, 1.0, 1.0)
    np.testing.assert_array_equal(series.read(range(T)), data)


def test_dims_mapped_by_name_and_unsupported_dtype(tmp_path):
    data = sample("int32")
    # stored as (x, time, lat, depth): names decide the axes, not the order
    stored = data.transpose(3, 0, 2, 1)
    ds = xr.Dataset(
        {"v": (("x", "time", "lat", "depth"), stored)},
        coords={"depth": np.arange(Z) * 2.5, "time": TIMES},
    )
    ds.to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr")
    assert series.shape == (T, Z, Y, X) and series.dtype == np.float32  # int32 -> float32
    np.testing.assert_array_equal(series.read(range(T)), data.astype(np.float32))
    assert series.spacing == (1.0, 1.0, 2.5)


def test_dims_order_override_and_squeeze(tmp_path):
    data = sample()
    stored = data.transpose(1, 0, 3, 2)[None]  # (member=1, a=z, b=t, c=x, d=y)
    xr.Dataset({"v": (("member", "a", "b", "c", "d"), stored)}).to_netcdf(
        tmp_path / "a.nc", engine="h5netcdf"
    )
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr", dims_order="b, a, d, c")
    np.testing.assert_array_equal(series.read(range(T)), data)
    with pytest.raises(ChronoclError, match="no time dimension") as info:
        ingest_netcdf(tmp_path / "a.nc", tmp_path / "t.zarr")
    assert "--time-dim" in one_line_error(info, ValueError)
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "t.zarr", time_dim="b")
    np.testing.assert_array_equal(series.read(range(T)), data.transpose(0, 1, 3, 2))
    with pytest.raises(ChronoclError, match="dims_order names nope") as info:
        ingest_netcdf(tmp_path / "a.nc", tmp_path / "u.zarr", dims_order=["b", "a", "d", "nope"])
    one_line_error(info, ValueError)


def test_variable_choice(tmp_path):
    data = sample()
    ds = dataset(data, u=(("time", "z", "y", "x"), data + 1), flat=(("y", "x"), data[0, 0]))
    ds.to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
    with pytest.raises(ChronoclError) as info:
        ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr")
    msg = one_line_error(info, ValueError)
    assert "choose the variable with --var" in msg
    assert "temp(time, z, y, x)" in msg and "u(time, z, y, x)" in msg and "flat(y, x)" in msg
    with pytest.raises(ChronoclError, match=r"no variable 'w'.*temp\(time") as info:
        ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr", var="w")
    one_line_error(info, ValueError)
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr", var="u")
    np.testing.assert_array_equal(series.read([1]), data[1:2] + 1)
    assert not (tmp_path / "t.zarr").exists()


def test_fill_values_need_nan_fill(tmp_path):
    data = sample()
    data[1, 2, 3, 4] = np.nan
    dataset(data).to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
    with pytest.raises(InvalidDataError, match=r"a.nc:temp step 1 has 1 NaN") as info:
        ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr")
    one_line_error(info)
    assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)
    series = ingest_netcdf(tmp_path / "a.nc", tmp_path / "s.zarr", nan_fill=-1.0)
    assert series.read([1])[0, 2, 3, 4] == -1.0


def test_missing_truncated_and_not_netcdf(tmp_path):
    with pytest.raises(InputNotFoundError) as info:
        ingest_netcdf(tmp_path / "gone.nc", tmp_path / "s.zarr")
    one_line_error(info, FileNotFoundError)
    (tmp_path / "text.nc").write_text("not a netcdf file\n")
    with pytest.raises(InvalidDataError, match=r"cannot read text.nc as NetCDF/HDF5") as info:
        ingest_netcdf(tmp_path / "text.nc", tmp_path / "s.zarr")
    one_line_error(info)
    big = np.random.default_rng(4).random((4, 8, 32, 32)).astype(np.float32)
    xr.Dataset({"v": (("time", "z", "y", "x"), big)}).to_netcdf(
        tmp_path / "a.nc", engine="h5netcdf"
    )
    raw = (tmp_path / "a.nc").read_bytes()
    for keep in (len(raw) // 2, len(raw) - 200):
        (tmp_path / "cut.nc").write_bytes(raw[:keep])
        with pytest.raises(InvalidDataError, match=r"cannot read cut.nc as NetCDF/HDF5") as info:
            ingest_netcdf(tmp_path / "cut.nc", tmp_path / "s.zarr")
        one_line_error(info, ValueError)
        assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)
