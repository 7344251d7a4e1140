"""xarray arrays in the API, and NetCDF / TIFF through `chronocl ingest` by file type."""

from __future__ import annotations

import numpy as np
import pandas as pd
import xarray as xr

import chronocl

from .test_cli import assert_one_line_error, cli


def dataarray(rng) -> xr.DataArray:
    data = rng.random((4, 3, 5, 6), dtype=np.float32)  # stored as (time, x, y, depth) below
    return xr.DataArray(
        np.transpose(data, (0, 3, 2, 1)).copy(),
        dims=("time", "x", "y", "depth"),
        coords={
            "time": pd.date_range("2026-01-01", periods=4, freq="h"),
            "depth": [0.0, 2.5, 5.0],
            "y": np.arange(5) * 0.5,
            "x": np.arange(6) * 0.25,
        },
        name="temp",
    ), data


def test_from_xarray_maps_dims_and_keeps_coordinates():
    array, data = dataarray(np.random.default_rng(0))
    series = chronocl.TimeSeries.from_array(array)
    assert series.shape == (4, 3, 5, 6) and series.spacing == (0.25, 0.5, 2.5)
    assert series.times[0].startswith("2026-01-01T00")
    np.testing.assert_array_equal(series.read(range(4)), data)
    lazy = chronocl.TimeSeries.from_array(array.chunk({"time": 1}))  # dask-backed stays lazy
    np.testing.assert_array_equal(lazy.read([2]), data[[2]])


def test_ingest_netcdf_and_tiff_by_file_type(tmp_path):
    import tifffile

    array, data = dataarray(np.random.default_rng(1))
    array.to_dataset().to_netcdf(tmp_path / "ocean.nc", engine="h5netcdf")
    result = cli("ingest", tmp_path / "ocean.nc", "-o", tmp_path / "o.zarr", "--var", "temp")
    assert result.returncode == 0, result.stderr
    np.testing.assert_array_equal(chronocl.open(tmp_path / "o.zarr").read(range(4)), data)
    for t in range(4):
        tifffile.imwrite(tmp_path / f"t{t}.tif", data[t], photometric="minisblack")
    result = cli("ingest", tmp_path / "t*.tif", "-o", tmp_path / "t.zarr")
    assert result.returncode == 0, result.stderr
    np.testing.assert_array_equal(chronocl.open(tmp_path / "t.zarr").read(range(4)), data)
    one = cli("ingest", tmp_path / "t0.tif", "-o", tmp_path / "one.zarr")
    assert_one_line_error(one, "one 3D stack")
    missing = cli("ingest", tmp_path / "ocean.nc", "-o", tmp_path / "m.zarr", "--var", "salt")
    assert_one_line_error(missing, "salt")
    assert not (tmp_path / "one.zarr").exists() and not (tmp_path / "m.zarr").exists()
