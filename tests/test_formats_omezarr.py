"""OME-Zarr input: NGFF 0.4 (zarr v2) and 0.5 (zarr v3) images opened in place as a TimeSeries."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

import chronocl
from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    StoreChangedError,
    StoreFormatError,
)
from chronocl.data.formats.omezarr import is_omezarr, open_omezarr

# Small synthetic data under the default transfer function leave some pictures empty (min);
# the warnings saying so (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")

AXES = {
    "t": {"name": "t", "type": "time", "unit": "second"},
    "c": {"name": "c", "type": "channel"},
    "z": {"name": "z", "type": "space", "unit": "micrometer"},
    "y": {"name": "y", "type": "space", "unit": "micrometer"},
    "x": {"name": "x", "type": "space", "unit": "micrometer"},
}


def _multiscales(axes: str, scales: list[list[float]], version: str | None = None) -> dict:
    ms = {
        "axes": [AXES[a] for a in axes],
        "datasets": [
            {"path": str(i), "coordinateTransformations": [{"type": "scale", "scale": s}]}
            for i, s in enumerate(scales)
        ],
    }
    if version:
        ms["version"] = version
    return ms


def _write(path, levels, axes, scales, zarr_format, chunks=None, top_scale=None):
    """Write an OME-Zarr image per NGFF 0.4 (zarr v2) or 0.5 (zarr v3, attrs['ome'])."""
    group = zarr.open_group(store=str(path), mode="w", zarr_format=zarr_format)
    for i, data in enumerate(levels):
        kw = {"dimension_names": list(axes)} if zarr_format == 3 else {}
        arr = group.create_array(
            str(i), shape=data.shape, dtype=data.dtype, chunks=chunks or data.shape, **kw
        )
        arr[...] = data
    if zarr_format == 2:
        ms = _multiscales(axes, scales, "0.4")
        if top_scale:
            ms["coordinateTransformations"] = [{"type": "scale", "scale": top_scale}]
        group.attrs["multiscales"] = [ms]
    else:
        group.attrs["ome"] = {"version": "0.5", "multiscales": [_multiscales(axes, scales)]}
    return group


def _files(path):
    return sorted(str(f.relative_to(path)) for f in path.rglob("*"))


def test_ngff04_channel_level_and_scale(tmp_path):
    rng = np.random.default_rng(0)
    full = rng.random((3, 2, 4, 6, 8)).astype(np.float32)  # t, c, z, y, x
    half = full[:, :, ::2, ::2, ::2].copy()
    path = tmp_path / "img.ome.zarr"
    _write(
        path,
        [full, half],
        "tczyx",
        [[0.5, 1, 2.0, 0.25, 0.25], [0.5, 1, 4.0, 0.5, 0.5]],
        2,
        chunks=(1, 1, 4, 6, 8),
        top_scale=[2.0, 1, 1, 1, 1],
    )
    assert is_omezarr(path)
    s = open_omezarr(path, channel=1, level=0)
    np.testing.assert_array_equal(s.data.compute(), full[:, 1])
    np.testing.assert_array_equal(s.read([2, 0], 1, 3), full[[2, 0], 1, 1:3])
    assert s.shape == (3, 4, 6, 8) and s.spacing == (0.25, 0.25, 2.0)
    assert s.times == (0.0, 1.0, 2.0)  # t * dt, dt = 0.5 * 2.0 (dataset and top-level scales)
    assert s.path == path and s._zarr is None  # a channel axis: reads go through dask
    assert s.vmin == pytest.approx(full[:, 1].min()) and s.vmax == pytest.approx(full[:, 1].max())
    low = open_omezarr(path, channel=0, level=1)
    np.testing.assert_array_equal(low.data.compute(), half[:, 0])
    assert low.shape == (3, 2, 3, 4) and low.spacing == (0.5, 0.5, 4.0)


def test_channels_are_variables_in_place_and_in_an_ingested_store(tmp_path, monkeypatch, capsys):
    """An image's channels are its series' variables (named by their omero labels); ingest
    --variables writes chosen channels, or all, as the variables of one store."""
    from chronocl.data.series import open_series

    from .test_vector_variables import one_line_error, run_cli

    rng = np.random.default_rng(1)
    full = rng.random((3, 3, 4, 6, 8)).astype(np.float32)  # t, c, z, y, x
    path = tmp_path / "cells.ome.zarr"
    group = _write(path, [full], "tczyx", [[1, 1, 1, 1, 1]], 2, chunks=(1, 1, 4, 6, 8))
    group.attrs["omero"] = {"channels": [{"label": "DAPI"}, {"label": "GFP 488"}, {}]}
    s = open_omezarr(path)
    assert s.variables == ("DAPI", "GFP_488", "c2")
    np.testing.assert_array_equal(s.variable("GFP_488").data.compute(), full[:, 1])
    with pytest.raises(ValueError, match="no variable 'RFP'"):
        s.variable("RFP")

    def ingest(out, names):
        return run_cli(
            monkeypatch, capsys, "ingest", path, "-o", tmp_path / out, "--variables", names
        )

    assert ingest("cells.zarr", "c2,DAPI")[0] == 0
    stored = open_series(tmp_path / "cells.zarr")
    assert stored.variables == ("c2", "DAPI")
    np.testing.assert_array_equal(stored.data.compute(), full[:, 2])
    np.testing.assert_array_equal(stored.variable("DAPI").data.compute(), full[:, 0])
    one_line_error(*ingest("x.zarr", "RFP"), "its channels: DAPI, GFP_488, c2")
    assert not (tmp_path / "x.zarr").exists()
    assert ingest("all.zarr", "all")[0] == 0
    assert open_series(tmp_path / "all.zarr").variables == s.variables


def test_ngff05_opens_in_place_with_fast_reads_and_statistics(tmp_path):
    data = np.arange(4 * 3 * 5 * 6, dtype=np.uint16).reshape(4, 3, 5, 6)
    path = tmp_path / "v05.zarr"
    _write(path, [data], "tzyx", [[1, 3.0, 2.0, 1.5]], 3, chunks=(1, 3, 5, 6))
    before = _files(path)
    assert is_omezarr(path)
    s = open_omezarr(path)
    assert _files(path) == before  # opened in place: nothing written
    assert isinstance(s._zarr, zarr.Array) and s.path == path
    np.testing.assert_array_equal(s.read([3, 1], 0, 2), data[[3, 1], 0:2])
    np.testing.assert_array_equal(s.read_brick([0]), np.moveaxis(data[[0]], 1, 0))
    assert (s.vmin, s.vmax) == (0, data.max()) and s.dtype == np.uint16
    np.testing.assert_allclose(s.stats.step_min, data.min(axis=(1, 2, 3)))
    np.testing.assert_allclose(s.stats.step_max, data.max(axis=(1, 2, 3)))
    np.testing.assert_allclose(s.stats.step_mean, data.mean(axis=(1, 2, 3)))
    assert s.spacing == (1.5, 2.0, 3.0) and s.times == (0, 1, 2, 3)


def test_an_image_read_in_place_is_unchanged_until_its_level_changes(tmp_path):
    data = np.zeros((4, 3, 5, 6), np.float32)
    path = tmp_path / "v05.zarr"
    _write(path, [data], "tzyx", [[1, 1, 1, 1]], 3, chunks=(1, 3, 5, 6))
    s = open_omezarr(path)
    s.check_unchanged()  # the level array "0" is what it was: no StoreChangedError
    zarr.open_array(store=str(path / "0"), mode="r+").resize((5, 3, 5, 6))
    with pytest.raises(StoreChangedError, match=r"now has shape \(5, 3, 5, 6\)"):
        s.check_unchanged()


def test_time_chunks_larger_than_one_and_other_axis_order_read_through_dask(tmp_path):
    data = np.random.default_rng(1).random((4, 3, 5, 6)).astype(np.float32)  # t, z, y, x
    path = tmp_path / "big.zarr"
    _write(path, [data], "tzyx", [[1, 1, 1, 1]], 3, chunks=(4, 3, 5, 6))
    s = open_omezarr(path)
    assert s._zarr is None
    np.testing.assert_array_equal(s.read([2]), data[[2]])
    # Axes stored as z, t, y, x are transposed to (T, Z, Y, X).
    path2 = tmp_path / "ztyx.zarr"
    _write(path2, [np.moveaxis(data, 0, 1).copy()], "ztyx", [[1, 1, 1, 1]], 2)
    s2 = open_omezarr(path2)
    assert s2._zarr is None
    np.testing.assert_array_equal(s2.data.compute(), data)


def test_errors_are_one_line_chronocl_value_errors(tmp_path):
    data = np.zeros((2, 3, 4, 5), np.float32)
    no_t = tmp_path / "zyx.zarr"
    _write(no_t, [data[0]], "zyx", [[1, 1, 1]], 2)
    with pytest.raises(ChronoclError, match="has axes z,y,x; a time series needs a t axis") as e:
        open_omezarr(no_t)
    assert isinstance(e.value, ValueError) and "\n" not in str(e.value)
    no_z = tmp_path / "tyx.zarr"
    _write(no_z, [data[:, 0]], "tyx", [[1, 1, 1]], 3)
    with pytest.raises(ValueError, match=r"has axes t,y,x; expected t, \[c,\] z, y, x"):
        open_omezarr(no_z)

    two = tmp_path / "two.zarr"
    _write(two, [data[:, None].repeat(2, axis=1)], "tczyx", [[1, 1, 1, 1, 1]], 2)
    with pytest.raises(ChronoclError, match=r"channel 2 is out of range.*2 channel"):
        open_omezarr(two, channel=2)
    with pytest.raises(ValueError, match=r"level 1 is out of range.*1 resolution level"):
        open_omezarr(two, level=1)
    with pytest.raises(ValueError, match="level -1 is out of range"):
        open_omezarr(two, level=-1)
    one = tmp_path / "one.zarr"
    _write(one, [data], "tzyx", [[1, 1, 1, 1]], 3)
    with pytest.raises(ValueError, match=r"channel 1 is out of range.*no channel axis"):
        open_omezarr(one, channel=1)
    plain = tmp_path / "plain.zarr"
    zarr.open_group(store=str(plain), mode="w")
    assert not is_omezarr(plain) and not is_omezarr(tmp_path / "missing")
    with pytest.raises(StoreFormatError, match="not an OME-Zarr image"):
        open_omezarr(plain)
    (tmp_path / "folder").mkdir()
    assert not is_omezarr(tmp_path / "folder")
    with pytest.raises(StoreFormatError, match="not a zarr group"):
        open_omezarr(tmp_path / "folder")
    with pytest.raises(InputNotFoundError, match="does not exist"):
        open_omezarr(tmp_path / "missing")


def test_an_images_own_levels_are_used_in_place_as_mean_levels(tmp_path):
    """Level 1 of the image (shape of chronocl's rule) is read as is for the "mean" pool, not
    pooled again; max/min and levels the image lacks are pooled on the fly; nothing is written."""
    from chronocl.data.pyramid import downsample

    rng = np.random.default_rng(3)
    full = rng.random((3, 1, 80, 6, 10), dtype=np.float32)  # t, c, z, y, x: longest axis 80
    own = np.full((3, 1, 40, 3, 5), 0.25, np.float32)  # not a pooling of `full`: must be read
    path = tmp_path / "img.ome.zarr"
    _write(path, [full, own], "tczyx", [[1, 1, 1, 1, 1], [1, 1, 2, 2, 2]], 3)
    before = _files(path)
    series = chronocl.open(path)
    assert series.n_levels == 2
    mean = series.level(1)
    np.testing.assert_array_equal(mean.read(range(3)), own[:, 0])
    assert mean.vmin == series.vmin and mean.spacing == (2.0, 2.0, 2.0)
    top = series.level(1, "max")
    np.testing.assert_array_equal(top.read([1])[0], downsample(full[1, 0], "max"))
    cv = chronocl.integrate(series, "0:3", "alpha", level=1)
    assert cv.shape == (40, 3, 5)
    assert _files(path) == before
