"""The .vti writer: VTK's own reader gets back exactly the arrays, spacing and extent written."""

from __future__ import annotations

import numpy as np
import pytest

from chronocl import Chronovolume
from chronocl.core.errors import InvalidParameterError, OutputExistsError
from chronocl.data.formats.vti import save_chronovolume_vti, write_vti

Z, Y, X = 3, 4, 5  # odd and all different, so an axis mix-up shows
SPACING = (0.5, 1.5, 2.5)  # dx, dy, dz


def read_vti(path):
    """(image, {name: (Z, Y, X[, components]) array}) of a .vti file, read back with VTK."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkXMLImageDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    image = reader.GetOutput()
    nx, ny, nz = image.GetDimensions()
    pd = image.GetPointData()
    arrays = {}
    for i in range(pd.GetNumberOfArrays()):
        a = pd.GetArray(i)
        comps = a.GetNumberOfComponents()
        shape = (nz, ny, nx) if comps == 1 else (nz, ny, nx, comps)
        arrays[a.GetName()] = vtk_to_numpy(a).reshape(shape)
    return image, arrays


def _chronovolume() -> Chronovolume:
    rng = np.random.default_rng(3)
    rgba = rng.random((Z, Y, X, 4), dtype=np.float32)
    t_index = rng.integers(-1, 9, size=(Z, Y, X), dtype=np.int32)
    sp = dict(zip("xyz", SPACING, strict=True))
    return Chronovolume(rgba=rgba, t_index=t_index, metadata={"spacing": sp})


def test_chronovolume_round_trip(tmp_path):
    pytest.importorskip("vtk")
    cv = _chronovolume()
    out = save_chronovolume_vti(cv, tmp_path / "cv.vti")
    assert out == tmp_path / "cv.vti"
    image, arrays = read_vti(out)
    assert image.GetDimensions() == (X, Y, Z)
    assert image.GetExtent() == (0, X - 1, 0, Y - 1, 0, Z - 1)
    assert image.GetSpacing() == SPACING
    assert image.GetOrigin() == (0.0, 0.0, 0.0)
    assert set(arrays) == {"rgba", "t_index"}
    assert arrays["rgba"].dtype == np.float32
    assert arrays["t_index"].dtype == np.int32
    np.testing.assert_array_equal(arrays["rgba"], cv.rgba)
    np.testing.assert_array_equal(arrays["t_index"], cv.t_index)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_chronovolume_without_t_index(tmp_path):
    pytest.importorskip("vtk")
    cv = _chronovolume()
    cv.t_index = None
    _, arrays = read_vti(save_chronovolume_vti(cv, tmp_path / "cv.vti"))
    assert set(arrays) == {"rgba"}


@pytest.mark.parametrize("dtype", ["uint8", "uint16", "int16", "int32", "float32", "float64"])
def test_dtypes_and_origin(tmp_path, dtype):
    pytest.importorskip("vtk")
    a = (np.arange(Z * Y * X) % 200).reshape(Z, Y, X).astype(dtype)
    big = a.astype(a.dtype.newbyteorder(">"))  # byte order of the input must not matter
    path = write_vti(tmp_path / "a.vti", {"a": a, "b": big}, spacing=SPACING, origin=(3, 2, 1))
    image, arrays = read_vti(path)
    assert image.GetOrigin() == (3.0, 2.0, 1.0)  # (ox, oy, oz) as given
    for name in ("a", "b"):
        assert arrays[name].dtype == np.dtype(dtype)
        np.testing.assert_array_equal(arrays[name], a)


def test_non_contiguous_input(tmp_path):
    pytest.importorskip("vtk")
    full = np.random.default_rng(1).random((X, Y, Z)).astype(np.float32)
    a = full.transpose(2, 1, 0)  # (Z, Y, X) view, not C-contiguous
    _, arrays = read_vti(write_vti(tmp_path / "a.vti", {"v": a}))
    np.testing.assert_array_equal(arrays["v"], a)


def test_header_is_plain_xml(tmp_path):
    path = write_vti(tmp_path / "a.vti", {"v": np.zeros((Z, Y, X), np.float32)}, SPACING)
    head = path.read_bytes().split(b"\n   _", 1)[0].decode()
    assert 'type="ImageData"' in head and 'header_type="UInt64"' in head
    assert f'WholeExtent="0 {X - 1} 0 {Y - 1} 0 {Z - 1}"' in head
    assert 'Spacing="0.5 1.5 2.5"' in head
    assert 'encoding="raw"' in head


def test_existing_output(tmp_path):
    arrays = {"v": np.zeros((Z, Y, X), np.float32)}
    path = write_vti(tmp_path / "a.vti", arrays)
    with pytest.raises(OutputExistsError, match="already exists"):
        write_vti(path, arrays)
    write_vti(path, {"v": np.ones((Z, Y, X), np.float32)}, overwrite=True)


@pytest.mark.parametrize(
    ("arrays", "match"),
    [
        ({}, "at least one array"),
        ({"a": np.zeros((Z, Y, X)), "b": np.zeros((Z, Y, X + 1))}, "grid"),
        ({"a b<": np.zeros((Z, Y, X))}, "name"),
        ({'a"': np.zeros((Z, Y, X))}, "name"),
        ({"a": np.zeros((Y, X))}, "shape"),
        ({"a": np.zeros((Z, Y, X), dtype=bool)}, "type"),
        ({"a": np.zeros((Z, Y, X), dtype=np.complex64)}, "type"),
    ],
)
def test_invalid_arrays(tmp_path, arrays, match):
    with pytest.raises(InvalidParameterError, match=match) as info:
        write_vti(tmp_path / "a.vti", arrays)
    assert "\n" not in str(info.value)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"spacing": (1, 0, 1)}, "spacing"),
        ({"spacing": (1, 1)}, "spacing"),
        ({"origin": (0, float("nan"), 0)}, "origin"),
        ({"origin": "abc"}, "origin"),
    ],
)
def test_invalid_geometry(tmp_path, kwargs, match):
    with pytest.raises(InvalidParameterError, match=match):
        write_vti(tmp_path / "a.vti", {"a": np.zeros((Z, Y, X))}, **kwargs)
