"""Chronovolume export to OME-Zarr (NGFF 0.4, zarr v2): round trip and the metadata written."""

from __future__ import annotations

import json

import numpy as np
import pytest
import zarr

from chronocl.core.errors import OutputExistsError, StoreFormatError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.formats.omezarr_chronovolume import (
    load_chronovolume_omezarr,
    save_chronovolume_omezarr,
)

META = {
    "dataset": "rand",
    "selection": {"steps": [1, 3, 5]},
    "spacing": {"x": 0.5, "y": 1.0, "z": 2.0},
    "value_range": [0.0, 1.0],
}


def _cv(t_index: bool = True) -> Chronovolume:
    rng = np.random.default_rng(0)
    rgba = rng.random((3, 4, 5, 4)).astype(np.float32)
    rgba[..., :3] *= rgba[..., 3:]  # premultiplied
    ti = rng.integers(-1, 6, size=(3, 4, 5)).astype(np.int32) if t_index else None
    return Chronovolume(rgba=rgba, t_index=ti, metadata=json.loads(json.dumps(META)))


def test_round_trip_is_exact(tmp_path):
    cv = _cv()
    out = save_chronovolume_omezarr(cv, tmp_path / "cv.ome.zarr")
    assert out == tmp_path / "cv.ome.zarr"
    back = load_chronovolume_omezarr(out)
    np.testing.assert_array_equal(back.rgba, cv.rgba)
    np.testing.assert_array_equal(back.t_index, cv.t_index)
    assert back.rgba.dtype == np.float32 and back.rgba.shape == (3, 4, 5, 4)
    assert back.t_index.dtype == np.int32
    assert back.metadata == META and back.spacing == (0.5, 1.0, 2.0)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no partial left
    with pytest.raises(OutputExistsError):
        save_chronovolume_omezarr(cv, out)
    no_ti = _cv(t_index=False)
    save_chronovolume_omezarr(no_ti, out, overwrite=True)
    back = load_chronovolume_omezarr(out)
    assert back.t_index is None and not (out / "labels").exists()
    np.testing.assert_array_equal(back.rgba, no_ti.rgba)


def test_written_attrs_follow_ngff_04(tmp_path):
    out = save_chronovolume_omezarr(_cv(), tmp_path / "cv.ome.zarr")
    assert (out / ".zgroup").exists() and (out / "0" / ".zarray").exists()  # zarr v2
    assert json.loads((out / "0" / ".zarray").read_text())["dimension_separator"] == "/"
    root = zarr.open_group(store=str(out), mode="r")
    attrs = dict(root.attrs)
    (ms,) = attrs["multiscales"]
    assert ms["version"] == "0.4"
    assert [a["name"] for a in ms["axes"]] == ["c", "z", "y", "x"]
    assert [a["type"] for a in ms["axes"]] == ["channel", "space", "space", "space"]
    (ds,) = ms["datasets"]
    assert ds["path"] == "0"
    assert ds["coordinateTransformations"] == [{"type": "scale", "scale": [1.0, 2.0, 1.0, 0.5]}]
    assert root["0"].shape == (4, 3, 4, 5) and root["0"].dtype == np.float32
    channels = attrs["omero"]["channels"]
    assert [c["label"] for c in channels] == ["red", "green", "blue", "alpha"]
    assert [c["color"] for c in channels] == ["FF0000", "00FF00", "0000FF", "FFFFFF"]
    for c in channels:
        assert c["window"] == {"start": 0.0, "end": 1.0, "min": 0.0, "max": 1.0}
    assert attrs["chronocl"]["premultiplied"] is True
    assert attrs["chronocl"]["metadata"] == META
    labels = root["labels"]
    assert dict(labels.attrs)["labels"] == ["t_index"]
    label = dict(labels["t_index"].attrs)
    assert "image-label" in label
    assert [a["name"] for a in label["multiscales"][0]["axes"]] == ["z", "y", "x"]
    assert labels["t_index"]["0"].dtype == np.int32


def test_load_rejects_other_stores(tmp_path):
    cv = _cv()
    cv.save(tmp_path / "native.zarr")
    with pytest.raises(StoreFormatError, match="not a chronovolume exported as OME-Zarr"):
        load_chronovolume_omezarr(tmp_path / "native.zarr")
    with pytest.raises(FileNotFoundError):
        load_chronovolume_omezarr(tmp_path / "missing.zarr")
