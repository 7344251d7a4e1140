"""Coordinates of NetCDF files and xarray arrays: a uniform one gives the spacing, a non-uniform
one is refused in one line, or resampled linearly to uniform spacing with --resample uniform."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import InvalidDataError

from .test_vector_variables import one_line_error, run_cli

xr = pytest.importorskip("xarray")
pytest.importorskip("h5netcdf")

DEPTH = np.array([0.0, 1.0, 3.0, 7.0, 15.0])  # non-uniform: steps 1, 2, 4, 8
LAT = np.array([40.0, 39.5, 39.0, 38.5])  # uniform, decreasing
LON = np.arange(6) * 0.1 + 1e-6 * np.array([0, 1, -1, 0, 1, 0])  # uniform within 1e-3


def data_array() -> xr.DataArray:
    values = np.random.default_rng(4).random((3, DEPTH.size, LAT.size, LON.size), np.float32)
    coords = {"time": [0.0, 1.0, 2.0], "depth": DEPTH, "lat": LAT, "lon": LON}
    return xr.DataArray(values, dims=tuple(coords), coords=coords, name="temp")


def expected_resampled(values: np.ndarray) -> np.ndarray:
    """Linear interpolation along depth onto 5 uniform samples 0, 3.75, ..., 15."""
    target = np.linspace(DEPTH[0], DEPTH[-1], DEPTH.size)
    return np.apply_along_axis(lambda col: np.interp(target, DEPTH, col), 1, values)


def test_netcdf_non_uniform_refused_or_resampled(tmp_path, monkeypatch, capsys):
    array = data_array()
    src = tmp_path / "ocean.nc"
    array.to_dataset().to_netcdf(src, engine="h5netcdf")
    out = tmp_path / "o.zarr"
    code, err = run_cli(monkeypatch, capsys, "ingest", src, "-o", out)
    one_line_error(code, err, "coordinate depth is not uniformly spaced")
    assert "--resample uniform" in err and not out.exists()
    code, err = run_cli(monkeypatch, capsys, "ingest", src, "-o", out, "--resample", "uniform")
    assert code == 0 and "note: depth: non-uniform coordinate" in err, err
    series = chronocl.open(out)
    assert series.spacing == pytest.approx((0.1, 0.5, 3.75), rel=1e-4)
    assert series.meta["resampled"][0].startswith("depth: non-uniform coordinate (steps 1 to 8)")
    np.testing.assert_allclose(series.read(range(3)), expected_resampled(array.values), rtol=1e-5)
    cubic = ("--resample", "cubic")
    code, err = run_cli(monkeypatch, capsys, "ingest", src, "-o", tmp_path / "c.zarr", *cubic)
    one_line_error(code, err, "unknown resample 'cubic'; choose uniform")
    assert not (tmp_path / "c.zarr").exists()


def test_xarray_non_uniform_refused_or_resampled():
    array = data_array()
    with pytest.raises(InvalidDataError, match="resample='uniform'"):
        chronocl.TimeSeries.from_array(array)
    series = chronocl.TimeSeries.from_array(array, resample="uniform")
    assert series.spacing == pytest.approx((0.1, 0.5, 3.75), rel=1e-4)
    assert series.meta["resampled"] and series.dtype == np.float32
    np.testing.assert_allclose(series.read(range(3)), expected_resampled(array.values), rtol=1e-5)
    uniform = array.isel(depth=[0, 1])  # depth steps 1: the spacing is the coordinate step
    assert chronocl.TimeSeries.from_array(uniform).spacing == pytest.approx((0.1, 0.5, 1.0))
    np.testing.assert_array_equal(chronocl.TimeSeries.from_array(uniform).read([1]), uniform[[1]])


def test_unsorted_coordinate_refused():
    array = data_array().assign_coords(depth=[0.0, 2.0, 1.0, 3.0, 4.0])
    for resample in (None, "uniform"):
        with pytest.raises(InvalidDataError, match="not strictly increasing or decreasing"):
            chronocl.TimeSeries.from_array(array, resample=resample)
