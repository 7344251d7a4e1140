"""TIFF ingest: 3D stacks per step and 4D files written by tifffile -> store -> same values."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import ChronoclError, InputNotFoundError, InvalidDataError
from chronocl.data.formats.tiff import ingest_tiff

tifffile = pytest.importorskip("tifffile")

T, Z, Y, X = 3, 5, 4, 6


def sample(dtype="uint16") -> np.ndarray:
    return (np.random.default_rng(5).random((T, Z, Y, X)) * 1000).astype(dtype)


def no_partial(folder) -> bool:
    return not [p for p in folder.iterdir() if ".partial-" in p.name]


def one_line_error(exc_info, kind=InvalidDataError) -> str:
    assert isinstance(exc_info.value, ChronoclError) and isinstance(exc_info.value, kind)
    msg = str(exc_info.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize("dtype", ["uint16", "float32", "uint8"])
def test_one_file_per_step(tmp_path, dtype):
    data = sample(dtype)
    for t in range(T):  # natural order: step10 would come after step9
        tifffile.imwrite(tmp_path / f"step{t}.tif", data[t])
    series = ingest_tiff([str(tmp_path / "step*.tif")], tmp_path / "s.zarr")
    reopened = chronocl.open(tmp_path / "s.zarr")
    for s in (series, reopened):
        assert s.shape == (T, Z, Y, X) and s.dtype == np.dtype(dtype)
        np.testing.assert_array_equal(s.read(range(T)), data)
        assert s.spacing == (1.0, 1.0, 1.0)
        assert s.vmin == data.min() and s.vmax == data.max()


@pytest.mark.parametrize("compression", [None, "zlib"])
def test_one_4d_file(tmp_path, compression):
    data = sample()
    tifffile.imwrite(tmp_path / "a.tif", data, metadata={"axes": "TZYX"}, compression=compression)
    series = ingest_tiff([tmp_path / "a.tif"], tmp_path / "s.zarr", spacing=(3, 2, 1))
    np.testing.assert_array_equal(series.read(range(T)), data)
    assert series.spacing == (3.0, 2.0, 1.0)


def test_z_before_t_and_int32(tmp_path):
    data = sample("int32")
    tifffile.imwrite(
        tmp_path / "a.tif",
        data.transpose(1, 0, 2, 3),
        metadata={"axes": "ZTYX"},
        photometric="minisblack",
    )
    series = ingest_tiff([tmp_path / "a.tif"], tmp_path / "s.zarr")
    assert series.dtype == np.float32  # int32 is stored as float32
    np.testing.assert_array_equal(series.read(range(T)), data.astype(np.float32))


def test_imagej_hyperstack_and_spacing(tmp_path):
    data = sample()
    tifffile.imwrite(
        tmp_path / "a.tif",
        data[:, :, None],  # C == 1
        imagej=True,
        resolution=(1 / 0.5, 1 / 0.25),
        metadata={"axes": "TZCYX", "spacing": 2.5, "unit": "um"},
    )
    series = ingest_tiff([tmp_path / "a.tif"], tmp_path / "s.zarr")
    np.testing.assert_array_equal(series.read(range(T)), data)
    assert series.spacing == (0.5, 0.25, 2.5)  # (dx, dy, dz)


def test_single_3d_file_and_channels(tmp_path):
    tifffile.imwrite(tmp_path / "one.tif", sample()[0])
    with pytest.raises(InvalidDataError, match=r"one.tif holds one 3D stack") as info:
        ingest_tiff([tmp_path / "one.tif"], tmp_path / "s.zarr")
    assert "4D (T, Z, Y, X)" in one_line_error(info, ValueError)
    tifffile.imwrite(
        tmp_path / "c.tif", np.zeros((T, Z, 2, Y, X), np.uint8), imagej=True,
        metadata={"axes": "TZCYX"},
    )  # fmt: skip
    with pytest.raises(InvalidDataError, match="2 channels") as info:
        ingest_tiff([tmp_path / "c.tif"], tmp_path / "s.zarr")
    one_line_error(info)
    assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)


def test_mixed_shapes_and_dtypes(tmp_path):
    data = sample()
    tifffile.imwrite(tmp_path / "s0.tif", data[0])
    tifffile.imwrite(tmp_path / "s1.tif", data[1, :, :, :5])
    with pytest.raises(InvalidDataError, match=r"s0.tif holds \(5, 4, 6\) but s1.tif") as info:
        ingest_tiff([tmp_path / "s0.tif", tmp_path / "s1.tif"], tmp_path / "s.zarr")
    one_line_error(info)
    tifffile.imwrite(tmp_path / "s1.tif", data[1].astype(np.float32))
    with pytest.raises(InvalidDataError, match="same data type") as info:
        ingest_tiff([str(tmp_path / "s*.tif")], tmp_path / "s.zarr")
    one_line_error(info)
    assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)


def test_missing_and_truncated(tmp_path):
    with pytest.raises(InputNotFoundError) as info:
        ingest_tiff([tmp_path / "gone.tif"], tmp_path / "s.zarr")
    one_line_error(info, FileNotFoundError)
    (tmp_path / "text.tif").write_text("not a tiff\n")
    with pytest.raises(InvalidDataError, match=r"cannot read text.tif as TIFF") as info:
        ingest_tiff([tmp_path / "text.tif"], tmp_path / "s.zarr")
    one_line_error(info)
    data = sample()
    for kw in ({}, {"compression": "zlib"}, {"imagej": True}):
        tifffile.imwrite(tmp_path / "a.tif", data, metadata={"axes": "TZYX"}, **kw)
        raw = (tmp_path / "a.tif").read_bytes()
        # 600 cuts into the image data, a third into the page directories (IFDs).
        for keep in (600, len(raw) // 3):
            (tmp_path / "cut.tif").write_bytes(raw[:keep])
            with pytest.raises(InvalidDataError, match=r"cannot read cut.tif as TIFF") as info:
                ingest_tiff([tmp_path / "cut.tif"], tmp_path / "s.zarr")
            one_line_error(info, ValueError)
            assert not (tmp_path / "s.zarr").exists() and no_partial(tmp_path)
