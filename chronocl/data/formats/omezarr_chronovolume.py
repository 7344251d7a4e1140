"""A chronovolume written as an OME-Zarr image (NGFF 0.4 on zarr v2) that napari can open, and
read back (`load_chronovolume_omezarr`). OME-Zarr images are read as series by
`chronocl.data.formats.omezarr`.

Layout of the written group::

    .zattrs        multiscales (axes c, z, y, x; one level "0" whose scale is
                   the chronovolume's spacing), omero (channels red, green,
                   blue, alpha, windows 0..1) and chronocl (metadata)
    0/             float32 (4, Z, Y, X): the RGBA channels, premultiplied by
                   alpha exactly as the chronovolume holds them
    labels/        present when the chronovolume has a t_index:
      t_index/0    int32 (Z, Y, X) label image (-1 where no step contributed)

NGFF 0.4 on zarr v2 (chunk keys separated by "/") is what napari-ome-zarr and
most other OME-Zarr readers read today.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import zarr

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import StoreFormatError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.formats.contract import Output
from chronocl.data.stores import open_group

FORMAT = "chronocl.chronovolume.omezarr"
NGFF_VERSION = "0.4"
CHANNELS = (("red", "FF0000"), ("green", "00FF00"), ("blue", "0000FF"), ("alpha", "FFFFFF"))
_SPACE_AXES = [{"name": n, "type": "space"} for n in ("z", "y", "x")]


def save_chronovolume_omezarr(
    cv: Chronovolume, path: str | os.PathLike, overwrite: bool = False
) -> Path:
    """Write `cv` as an OME-Zarr image (NGFF 0.4, zarr v2) atomically; returns the path."""
    rgba = cv.float_rgba()  # a display chronovolume's RGBA8 as float32
    if rgba.ndim != 4 or rgba.shape[3] != 4:
        raise StoreFormatError(f"chronovolume rgba has shape {rgba.shape}; expected (Z, Y, X, 4)")
    z, y, x, _ = rgba.shape
    zc = max(1, min(z, (8 * 2**20) // max(1, y * x * 4)))
    scale = [float(s) for s in cv.spacing_zyx]  # the axes are z, y, x
    with atomic_directory(path, overwrite) as tmp:
        root = zarr.open_group(store=str(tmp), mode="w", zarr_format=2)
        _create(root, "0", np.moveaxis(rgba, 3, 0), (1, zc, y, x))
        root.attrs.update(
            {
                "multiscales": [
                    {
                        "version": NGFF_VERSION,
                        "name": "chronovolume",
                        "axes": [{"name": "c", "type": "channel"}, *_SPACE_AXES],
                        "datasets": [_dataset([1.0, *scale])],
                        "type": "none",
                        "metadata": {"description": "RGBA premultiplied by alpha"},
                    }
                ],
                "omero": {
                    "version": NGFF_VERSION,
                    "name": "chronovolume",
                    "rdefs": {"model": "color", "defaultZ": z // 2, "defaultT": 0},
                    "channels": [_channel(label, color) for label, color in CHANNELS],
                },
                "chronocl": {
                    "format": FORMAT,
                    "version": 1,
                    "premultiplied": True,
                    "channels": [label for label, _ in CHANNELS],
                    "metadata": cv.metadata,
                },
            }
        )
        if cv.t_index is not None:
            t_index = np.asarray(cv.t_index, dtype=np.int32)
            if t_index.shape != (z, y, x):
                raise StoreFormatError(
                    f"chronovolume t_index has shape {t_index.shape}; expected {(z, y, x)}"
                )
            labels = root.create_group("labels")
            labels.attrs["labels"] = ["t_index"]
            label = labels.create_group("t_index")
            _create(label, "0", t_index, (zc, y, x))
            label.attrs.update(
                {
                    "multiscales": [
                        {
                            "version": NGFF_VERSION,
                            "name": "t_index",
                            "axes": list(_SPACE_AXES),
                            "datasets": [_dataset(scale)],
                        }
                    ],
                    "image-label": {"version": NGFF_VERSION, "source": {"image": "../../"}},
                }
            )
    return Path(path)


def load_chronovolume_omezarr(path: str | os.PathLike) -> Chronovolume:
    """Read a chronovolume written by `save_chronovolume_omezarr`."""
    p = Path(path)
    root = open_group(p, "OME-Zarr chronovolume")
    attrs = dict(root.attrs).get("chronocl", {})
    if not isinstance(attrs, dict) or attrs.get("format") != FORMAT or "0" not in root:
        raise StoreFormatError(f"{str(p)!r} is not a chronovolume exported as OME-Zarr by chronocl")
    rgba = np.ascontiguousarray(np.moveaxis(np.asarray(root["0"][...]), 0, 3), dtype=np.float32)
    t_index = None
    if "labels" in root and "t_index" in root["labels"]:
        t_index = np.asarray(root["labels"]["t_index"]["0"][...], dtype=np.int32)
    return Chronovolume(rgba=rgba, t_index=t_index, metadata=dict(attrs.get("metadata", {})))


def _create(group: zarr.Group, name: str, data: np.ndarray, chunks: tuple[int, ...]) -> None:
    """A zarr v2 array with "/"-separated chunk keys, as NGFF 0.4 asks."""
    arr = group.create_array(
        name,
        shape=data.shape,
        dtype=data.dtype,
        chunks=chunks,
        chunk_key_encoding={"name": "v2", "separator": "/"},
    )
    arr[...] = data


def _dataset(scale: list[float]) -> dict:
    return {"path": "0", "coordinateTransformations": [{"type": "scale", "scale": scale}]}


def _channel(label: str, color: str) -> dict:
    return {
        "label": label,
        "color": color,
        "active": label != "alpha",
        "coefficient": 1,
        "family": "linear",
        "inverted": False,
        "window": {"start": 0.0, "end": 1.0, "min": 0.0, "max": 1.0},
    }


OUTPUT = Output(".ome.zarr", "napari", save_chronovolume_omezarr)
