"""Formats through the command line and `chronocl.open`: OME-Zarr in place and ingested,
chronovolume outputs chosen by suffix, series export, and option misuse."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import ChronoclError
from chronocl.data.ingest import ingest

from .test_cli import assert_one_line_error, cli
from .test_formats_omezarr import _write


@pytest.fixture
def omezarr(tmp_path):
    data = np.random.default_rng(3).random((4, 2, 5, 6, 7), dtype=np.float32)  # t, c, z, y, x
    path = tmp_path / "img.ome.zarr"
    _write(path, [data], "tczyx", [[1, 1, 2.0, 0.5, 0.5]], zarr_format=2, chunks=(2, 1, 5, 6, 7))
    return path, data


def test_open_omezarr_in_place_and_integrate(omezarr):
    path, data = omezarr
    series = chronocl.open(path)
    assert series.shape == (4, 5, 6, 7) and series.spacing == (0.5, 0.5, 2.0)
    np.testing.assert_array_equal(series.read(range(4)), data[:, 0])
    ref = chronocl.integrate(series, "0:4", "max", engine="numpy")
    np.testing.assert_allclose(chronocl.integrate(series, "0:4", "max").rgba, ref.rgba, atol=1e-5)


def test_ingest_omezarr_channel_into_a_store(omezarr, tmp_path):
    path, data = omezarr
    result = cli("ingest", path, "-o", tmp_path / "s.zarr", "--channel", "1")
    assert result.returncode == 0, result.stderr
    series = chronocl.open(tmp_path / "s.zarr")
    np.testing.assert_array_equal(series.read(range(4)), data[:, 1])
    assert series.data.chunksize[0] == 1 and series.spacing == (0.5, 0.5, 2.0)


def test_chronovolume_outputs_by_suffix(tmp_path):
    import vtk
    from vtk.util.numpy_support import vtk_to_numpy

    from chronocl.data.formats.omezarr_chronovolume import load_chronovolume_omezarr

    series = chronocl.TimeSeries.from_array(np.random.default_rng(1).random((5, 3, 4, 6)))
    store = tmp_path / "s.zarr"
    series.save(store)
    cv = chronocl.integrate(series, "0:5", "max", engine="numpy")
    for name in ("cv.zarr", "cv.ome.zarr", "cv.vti"):
        result = cli("integrate", store, tmp_path / name, "--mode", "max", "--engine", "numpy")
        assert result.returncode == 0, result.stderr
    np.testing.assert_array_equal(chronocl.Chronovolume.load(tmp_path / "cv.zarr").rgba, cv.rgba)
    back = load_chronovolume_omezarr(tmp_path / "cv.ome.zarr")
    np.testing.assert_array_equal(back.rgba, cv.rgba)
    np.testing.assert_array_equal(back.t_index, cv.t_index)
    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(tmp_path / "cv.vti"))
    reader.Update()
    rgba = vtk_to_numpy(reader.GetOutput().GetPointData().GetArray("rgba")).reshape(3, 4, 6, 4)
    np.testing.assert_array_equal(rgba, cv.rgba)


def test_export_command(tmp_path):
    series = chronocl.TimeSeries.from_array(np.random.default_rng(2).random((6, 3, 4, 5)))
    series.save(tmp_path / "s.zarr")
    result = cli(
        "export",
        tmp_path / "s.zarr",
        "-o",
        tmp_path / "w.npy",
        "--format",
        "npy",
        "--window",
        "0:6:2",
        "--z",
        "1:3",
    )
    assert result.returncode == 0, result.stderr
    np.testing.assert_array_equal(np.load(tmp_path / "w.npy"), series.read([0, 2, 4], 1, 3))


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["integrate", "{s}", "{tmp}/cv.png"], "end it in .zarr"),
        (["ingest", "{tmp}/a.npy", "-o", "{tmp}/o.zarr", "--var", "temp"], "--var applies to"),
        (["ingest", "{tmp}/a.npy", "-o", "{tmp}/o.zarr", "--format", "hdf4"], "unknown format"),
        (["export", "{s}", "-o", "{tmp}/e", "--format", "xls"], "vti, npy, raw"),
    ],
)
def test_format_misuse(tmp_path, args, needle):
    series = chronocl.TimeSeries.from_array(np.zeros((2, 2, 2, 2), dtype=np.float32))
    series.save(tmp_path / "s.zarr")
    np.save(tmp_path / "a.npy", np.zeros((2, 2, 2, 2), dtype=np.float32))
    argv = [a.format(s=tmp_path / "s.zarr", tmp=tmp_path) for a in args]
    assert_one_line_error(cli(*argv), needle)


def test_spacing_is_refused_for_self_describing_formats(omezarr, tmp_path):
    with pytest.raises(ChronoclError, match="--spacing applies to"):
        ingest([omezarr[0]], tmp_path / "o.zarr", spacing=(1, 1, 1))
