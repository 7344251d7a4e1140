"""Reads of a series' zarr array and the check that its store is unchanged, for `TimeSeries`.

Steps are read in runs of evenly spaced steps (`step_runs`), one zarr call a run, decoding
straight into the caller's brick through the damage checks of `chronocl.data.integrity`
(`read_runs`), or chunk by chunk on the host threads where `chronocl.data.chunk_reads` decodes
the store directly. The stamp of the array's metadata file tells cheaply whether the store may have
changed (`metadata_stamp`); `stored_shape` then reads the shape it has now.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import zarr
from zarr.buffer import default_buffer_prototype

from chronocl.data.chunk_reads import read_steps
from chronocl.data.integrity import checked_read


def step_runs(steps: Sequence[int], most: int) -> list[tuple[int, int, slice]]:
    """Split `steps` into runs of at most `most` evenly spaced, increasing steps.

    Each run is (i0, i1, slice): steps[i0:i1] are the stored steps the slice selects.
    """
    runs, i, n = [], 0, len(steps)
    while i < n:
        j = i + 1
        if j < n and most > 1 and steps[j] > steps[i]:
            d = steps[j] - steps[i]
            while j + 1 < n and j + 1 - i < most and steps[j + 1] - steps[j] == d:
                j += 1
            j += 1
        else:
            d = 1
        runs.append((i, j, slice(int(steps[i]), int(steps[j - 1]) + 1, int(d))))
        i = j
    return runs


def read_runs(
    path: Path | None,
    arr: zarr.Array,
    steps: Sequence[int],
    z0: int,
    z1: int,
    out: np.ndarray,
    per_call: int,
) -> None:
    """Fill the xytz brick `out` (z1 - z0, W, Y, X) with z rows [z0, z1) of `steps` of `arr`.

    Up to `per_call` evenly spaced steps go in one call: zarr fetches and decodes the chunks of
    one call concurrently, where one call per step would decode them one at a time.
    """
    if read_steps(path, arr, steps, z0, z1, out):  # a local store's chunks, decoded directly
        return
    wrap = default_buffer_prototype().nd_buffer.from_numpy_array
    for i0, i1, run in step_runs(steps, per_call):
        # (rows, n, Y, X) of the brick seen as (n, rows, Y, X), the store's order.
        view = out[:, i0:i1].transpose(1, 0, 2, 3)
        selection = (run, slice(z0, z1))
        checked_read(
            path,
            arr,
            lambda sel=selection, v=view: arr.get_basic_selection(sel, out=wrap(v)),
            selection,
        )


def metadata_file(path: Path, arr: zarr.Array) -> Path | None:
    """The file holding an array's shape in a local store (zarr v3 or v2), if there is one."""
    folder = Path(path) / arr.path if arr.path else Path(path)
    for name in ("zarr.json", ".zarray"):
        if (folder / name).is_file():
            return folder / name
    return None


def metadata_stamp(path: Path, arr: zarr.Array) -> int | None:
    """The modification time (ns) of `arr`'s metadata file, None where it has none."""
    meta = metadata_file(path, arr)
    return meta.stat().st_mtime_ns if meta is not None else None


def stored_stats(path: Path) -> tuple | None:
    """The statistics a chronocl store at `path` keeps now (vmin, vmax and the per-step lists,
    as `metadata.SeriesStats` orders them); None where it keeps none (a bare array) or is gone."""
    try:
        attrs = dict(zarr.open(store=str(path), mode="r").attrs).get("chronocl", {})
        keys = ("vmin", "vmax", "step_min", "step_max", "step_mean")
        return tuple(tuple(attrs[k]) if isinstance(attrs[k], list) else attrs[k] for k in keys)
    except Exception:
        return None


def stored_shape(path: Path, arr: zarr.Array) -> tuple[int, ...] | None:
    """The shape the array at `arr`'s place in the store at `path` has now; None if gone."""
    try:
        node = zarr.open(store=str(path), mode="r")
        inner = arr.path  # "data" in a chronocl store, "" for a bare array
        return tuple((node[inner] if isinstance(node, zarr.Group) else node).shape)
    except Exception:
        return None
