"""export_series: .vti + .pvd (read back with VTK), .npy and raw + JSON sidecar, subsets, errors."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from chronocl import TimeSeries
from chronocl.core.errors import (
    InvalidParameterError,
    InvalidSelectionError,
    OutputExistsError,
    UnknownNameError,
)
from chronocl.data.formats.export import export_series, parse_slab
from chronocl.data.formats.raw import ingest_raw

from .test_export_vti import read_vti

T, Z, Y, X = 6, 5, 4, 3  # all different, so an axis mix-up shows
SPACING = (0.5, 1.5, 2.0)  # dx, dy, dz


def _series(dtype=np.float32, times=None) -> TimeSeries:
    rng = np.random.default_rng(11)
    if np.dtype(dtype).kind == "f":
        data = rng.standard_normal((T, Z, Y, X)).astype(dtype)
    else:
        data = rng.integers(0, 1000, size=(T, Z, Y, X)).astype(dtype)
    return TimeSeries.from_array(data, spacing=SPACING, times=times)


def _read_vti(path):
    image, arrays = read_vti(path)
    return image, arrays["value"]


def _read_pvd(path):
    """Time steps and arrays of a .pvd (VTK has no PVD reader; ParaView's is vtkPVDReader)."""
    root = ET.parse(path).getroot()
    assert root.tag == "VTKFile" and root.get("type") == "Collection"
    datasets = root.find("Collection").findall("DataSet")
    times = [float(d.get("timestep")) for d in datasets]
    steps = [_read_vti(path.parent / d.get("file"))[1] for d in datasets]
    return times, steps


def test_vti_all_steps(tmp_path):
    pytest.importorskip("vtk")
    series = _series()
    out = tmp_path / "series_vti"
    paths = export_series(series, out, fmt="vti")
    assert paths[0] == out / "series_vti.pvd"
    assert [p.name for p in paths[1:]] == [f"series_vti_t{s:05d}.vti" for s in range(T)]
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in paths)
    expected = series.read(range(T))
    for s, p in enumerate(paths[1:]):
        image, values = _read_vti(p)
        assert image.GetSpacing() == SPACING
        assert image.GetExtent() == (0, X - 1, 0, Y - 1, 0, Z - 1)
        assert values.dtype == np.float32
        np.testing.assert_array_equal(values, expected[s])
    times, steps = _read_pvd(paths[0])
    assert times == [float(s) for s in range(T)]
    for s in range(T):
        np.testing.assert_array_equal(steps[s], expected[s])
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_vti_window_slab_and_time_labels(tmp_path):
    pytest.importorskip("vtk")
    series = _series(np.uint16, times=[0.0, 0.25, 0.5, 0.75, 1.0, 1.25])
    paths = export_series(series, tmp_path / "sub", fmt="vti", window="1:6:2", z="1:4")
    assert [p.name for p in paths[1:]] == ["sub_t00001.vti", "sub_t00003.vti", "sub_t00005.vti"]
    times, steps = _read_pvd(paths[0])
    assert times == [0.25, 0.75, 1.25]
    expected = series.read([1, 3, 5], 1, 4)
    for i, p in enumerate(paths[1:]):
        image, values = _read_vti(p)
        assert image.GetOrigin() == (0.0, 0.0, 1 * SPACING[2])
        assert image.GetDimensions() == (X, Y, 3)
        assert values.dtype == np.uint16
        np.testing.assert_array_equal(values, expected[i])
        np.testing.assert_array_equal(steps[i], expected[i])


def test_pvd_uses_step_index_for_text_labels(tmp_path):
    series = _series(times=[f"day{i}" for i in range(T)])
    paths = export_series(series, tmp_path / "d", fmt="vti", window="2,4")
    text = paths[0].read_text()
    assert 'timestep="2" group="" part="0" file="d_t00002.vti"' in text
    assert 'timestep="4" group="" part="0" file="d_t00004.vti"' in text


@pytest.mark.parametrize(
    ("window", "z", "steps"),
    [(None, None, list(range(T))), ("0:6:3", "2:", [0, 3]), ([1, 4], ":1", [1, 4])],
)
def test_npy(tmp_path, window, z, steps):
    series = _series(np.int16)
    out = tmp_path / "sel.npy"
    assert export_series(series, out, fmt="npy", window=window, z=z) == [out]
    z0, z1 = parse_slab(z, Z)
    got = np.load(out)
    assert got.dtype == np.int16
    np.testing.assert_array_equal(got, series.read(steps, z0, z1))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_npy_without_suffix_keeps_the_name(tmp_path):
    out = tmp_path / "plain"
    export_series(_series(), out, fmt="npy", window="0:2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain"]
    assert np.load(out).shape == (2, Z, Y, X)


def test_raw_files_and_sidecar(tmp_path):
    series = _series(np.uint16)
    out = tmp_path / "rawdir"
    paths = export_series(series, out, fmt="raw", window="1:5", z="1:3")
    assert paths[0] == out / "rawdir.json"
    names = [f"rawdir_t{s:05d}.raw" for s in range(1, 5)]
    assert [p.name for p in paths[1:]] == names
    meta = json.loads(paths[0].read_text())
    assert meta["dims"] == [X, Y, 2]
    assert meta["dtype"] == "uint16"
    assert meta["endian"] == "little"
    assert meta["spacing"] == dict(zip("xyz", SPACING, strict=True))
    assert meta["steps"] == [1, 2, 3, 4]
    assert meta["files"] == names
    expected = series.read([1, 2, 3, 4], 1, 3)
    for i, p in enumerate(paths[1:]):
        assert p.read_bytes() == expected[i].astype("<u2").tobytes()


def test_raw_reads_back_with_ingest(tmp_path):
    series = _series(np.float32, times=[10, 20, 30, 40, 50, 60])
    paths = export_series(series, tmp_path / "r", fmt="raw")
    meta = json.loads(paths[0].read_text())
    sp = meta["spacing"]
    back = ingest_raw(
        [str(p) for p in paths[1:]],
        tmp_path / "back.zarr",
        dims=meta["dims"],
        dtype=meta["dtype"],
        endian=meta["endian"],
        spacing=(sp["x"], sp["y"], sp["z"]),
        times=meta["times"],
    )
    np.testing.assert_array_equal(back.read(range(T)), series.read(range(T)))
    assert back.spacing == SPACING
    assert back.times == series.times


def test_unknown_format(tmp_path):
    with pytest.raises(UnknownNameError, match="vti, npy, raw") as info:
        export_series(_series(), tmp_path / "x", fmt="hdf5")
    assert "\n" not in str(info.value)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("fmt", ["vti", "npy", "raw"])
def test_existing_output(tmp_path, fmt):
    series = _series()
    out = tmp_path / f"out.{fmt}" if fmt == "npy" else tmp_path / "out"
    export_series(series, out, fmt=fmt, window="0:2")
    with pytest.raises(OutputExistsError, match="already exists") as info:
        export_series(series, out, fmt=fmt, window="0:3")
    assert "\n" not in str(info.value)
    paths = export_series(series, out, fmt=fmt, window="0:3", overwrite=True)
    assert len(paths) == (1 if fmt == "npy" else 4)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    if fmt != "npy":
        assert len(list(out.iterdir())) == 4  # the old export was replaced, not merged


@pytest.mark.parametrize("z", ["3:3", "0:6", "-1:2", "a:b", "1", "1:2:3", (4, 2)])
def test_bad_slab(tmp_path, z):
    with pytest.raises(InvalidParameterError, match="z slab"):
        export_series(_series(), tmp_path / "x", fmt="npy", z=z)
    assert not list(tmp_path.iterdir())


def test_bad_window(tmp_path):
    with pytest.raises(InvalidSelectionError):
        export_series(_series(), tmp_path / "x", fmt="raw", window="4:99")
    assert not list(tmp_path.iterdir())
