"""TimeSeries: a time-varying volume (T, Z, Y, X) over a zarr store, read lazily through dask.

A series opens from a chronocl store (zarr v3 written by `chronocl.data.writer`, v2 read), whose
attribute ``chronocl`` holds its statistics, spacing and time labels; from a bare zarr array (v2
or v3) without them, whose statistics are then computed in one dask pass; or from any array
(`TimeSeries.from_array`, checked in `chronocl.data.array_fields`). A store's array is opened in
`chronocl.data.store_open`; reads of a zarr-backed series go to zarr directly
(`chronocl.data.store_reads`), decoding straight into the caller's buffer, and through
`chronocl.data.integrity` so damage is never read as zeros.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import dask.array as da
import numpy as np
import zarr

from chronocl.core.errors import StoreChangedError, UnknownNameError
from chronocl.core.host_threads import copy_all
from chronocl.core.memory import aligned_empty
from chronocl.core.tuning import TUNING
from chronocl.core.values import normalize
from chronocl.data.array_fields import array_fields
from chronocl.data.chunk_reads import read_rows
from chronocl.data.integrity import checked_read
from chronocl.data.level_sources import POOLED, STORED, LevelSource
from chronocl.data.metadata import SeriesStats
from chronocl.data.pyramid import check_pool, describe_levels
from chronocl.data.sizes import disk_usage, human_size
from chronocl.data.steps import Steps
from chronocl.data.store_open import open_array
from chronocl.data.store_reads import metadata_stamp, read_runs, stored_shape, stored_stats
from chronocl.data.writer import VARIABLES, write_store


@dataclass
class TimeSeries:
    """A (T, Z, Y, X) series with its statistics, voxel spacing and time labels.

    `spacing` is (dx, dy, dz), x first, like every per-axis triple of the API (`dims`, probe
    points and boxes); only array shapes (`shape`, `volume_shape`) follow the array's (T, Z,
    Y, X). `level_index` is 0 for the series itself, n for its coarse level n (`level(n)`).

    A reader that is not a chronocl store's says where the coarse levels come from
    (`level_source`, `chronocl.data.level_sources`) and how another variable of the same source
    opens (`open_variable`, given a name `variables` lists); by default levels are the store's
    own (or pooled on the fly in memory) and variables the store's.
    """

    data: da.Array
    stats: SeriesStats
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)  # (dx, dy, dz), x first
    times: tuple = ()
    source: str = ""
    path: Path | None = None
    _zarr: zarr.Array | None = field(default=None, repr=False)
    _stamp: int | None = field(default=None, repr=False)
    level_index: int = 0
    _root: TimeSeries | None = field(default=None, repr=False)
    _levels: dict = field(default_factory=dict, repr=False)  # the levels built, by (n, pool)
    # What a store records beside the data (`writer.EXTRA_KEYS`): the variable's name and the
    # store's variables, a derived quantity and its components, resampling notes.
    meta: dict = field(default_factory=dict, repr=False)
    # Where the coarse levels come from; None: the store's (`path`), else pooled on the fly.
    level_source: LevelSource | None = field(default=None, repr=False)
    # Opens another variable of the same source by name where it is not a chronocl store's
    # (an OME-Zarr image's channels, read in place).
    open_variable: Callable[[str], TimeSeries] | None = field(default=None, repr=False)
    # The numpy array `data` wraps, for a series made from one (`from_array`): its steps are
    # read in place (`chronocl.data.bricks.SlotBrick`), not copied out through dask.
    host: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.times:
            self.times = tuple(range(self.n_steps))
        if self.path is not None and self._zarr is not None:
            self._stamp = metadata_stamp(self.path, self._zarr)

    def stored_in(self, path: Path, arr: zarr.Array | None = None) -> TimeSeries:
        """Note that this series is read from the store at `path`; returns the series.

        `arr`, the zarr array of that store which `data` wraps step for step, makes reads go
        to zarr directly and lets `check_unchanged` tell when the store changes.
        """
        self.path, self._zarr = path, arr
        self.__post_init__()
        return self

    @property
    def zarr_array(self) -> zarr.Array | None:
        """The zarr array `data` wraps step for step, which reads go to directly; None where
        they go through dask. Set for a store read in place (`chronocl.data.remote`)."""
        return self._zarr

    @zarr_array.setter
    def zarr_array(self, arr: zarr.Array | None) -> None:
        self._zarr = arr

    # -- shape ---------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int, int]:
        return tuple(int(n) for n in self.data.shape)  # type: ignore[return-value]

    @property
    def n_steps(self) -> int:
        return self.shape[0]

    @property
    def volume_shape(self) -> tuple[int, int, int]:
        """(Z, Y, X) of one step: the array's shape (`dims` is the same, x first)."""
        return self.shape[1:]  # type: ignore[return-value]

    @property
    def dims(self) -> tuple[int, int, int]:
        """(nx, ny, nz), x first: voxels along each axis of one step (`ingest --dims`)."""
        return self.shape[:0:-1]  # type: ignore[return-value]

    @property
    def spacing_zyx(self) -> tuple[float, float, float]:
        """(dz, dy, dx): `spacing` in the array's axis order, for code indexing (Z, Y, X)."""
        return self.spacing[::-1]  # type: ignore[return-value]

    @property
    def time_unit(self) -> str | None:
        """The unit of the steps' numeric times ('s', 'days'), None where the store names none."""
        return self.meta.get("time_unit")

    @property
    def dtype(self) -> np.dtype:
        return self.data.dtype

    @property
    def vmin(self) -> float:
        return self.stats.vmin

    @property
    def vmax(self) -> float:
        return self.stats.vmax

    # -- variables (docs/variables.md) -------------------------------------------------------
    @property
    def variables(self) -> tuple[str, ...]:
        """The variables of the store this series was opened from (first: the store's own)."""
        names = self.meta.get("variables") or [self.meta.get("variable")]
        return tuple(str(n) for n in names if n)

    def variable(self, name: str) -> TimeSeries:
        """The series of variable `name` of this series' store (`variables` lists them)."""
        names, own = self.variables, self.meta.get("variable")
        root = self.path
        if root is not None and own is not None and own != names[0]:
            root = root.parent.parent  # this is VARIABLES/<own> inside the store
        if name not in names:
            where = f"store {str(root)!r}" if root is not None else self.source
            found = ", ".join(names) if names else "one unnamed variable"
            raise UnknownNameError(f"{where} has no variable {name!r}; it holds {found}")
        if name == own:
            return self
        if self.open_variable is not None:
            return self.open_variable(name)
        if root is None:
            return self
        return open_store(root if name == names[0] else root / VARIABLES / name)

    # -- coarse levels (chronocl.data.pyramid) -------------------------------------------------
    @property
    def n_levels(self) -> int:
        """1 + the coarse levels: stored ones, or (in memory) those `level_shapes` gives."""
        root = self._root or self
        return root._source().count(root)

    def _source(self) -> LevelSource:
        if self.level_source is not None:
            return self.level_source
        return STORED if self.path is not None else POOLED

    def level(self, n: int, pool: str = "mean") -> TimeSeries:
        """Coarse level `n` pooled by `pool` (mean, max, min); level 0 is the series itself.

        Its stats keep level 0's vmin/vmax (one TF maps a value alike at every level) with the
        level's own per-step statistics; its spacing keeps level 0's physical extent.
        """
        root = self._root or self
        check_pool(pool)
        if n == 0 and not isinstance(n, bool):
            return root
        if (n, pool) not in root._levels:
            parts = root._source().parts(root, n, pool)
            root._levels[n, pool] = dataclasses.replace(
                root,
                data=parts.data,
                stats=parts.stats,
                spacing=parts.spacing,
                _zarr=parts.array,
                level_index=int(n),
                _root=root,
                _levels={},
                host=None,
            )
        return root._levels[n, pool]

    # -- reading -------------------------------------------------------------------------
    def read(self, steps: Sequence[int], z0: int = 0, z1: int | None = None) -> np.ndarray:
        """Raw values of the given steps and z rows: (W, z1 - z0, Y, X)."""
        return np.moveaxis(self.read_brick(steps, z0, z1), 1, 0)

    def read_brick(
        self,
        steps: Sequence[int],
        z0: int = 0,
        z1: int | None = None,
        out: np.ndarray | None = None,
        per_call: int | None = None,
    ) -> np.ndarray:
        """Raw values of z rows [z0, z1) of the given steps as an xytz brick (z1 - z0, W, Y, X).

        `out`, if given, is filled and returned (a C-contiguous array of that shape and dtype).
        A zarr store is read up to `per_call` evenly spaced steps per call, decoding straight
        into the brick: zarr fetches and decodes the chunks of one call concurrently, where
        one call per step would decode them one at a time (None: `TUNING.steps_per_read`).
        """
        per_call = TUNING.steps_per_read if per_call is None else per_call
        z1 = self.shape[1] if z1 is None else z1
        if out is None:
            out = aligned_empty((z1 - z0, len(steps), *self.shape[2:]), self.dtype)
        if self._zarr is None:
            copy_all([(out[:, i], self.step_rows(int(s), z0, z1)) for i, s in enumerate(steps)])
            return out
        read_runs(self.path, self._zarr, steps, z0, z1, out, per_call)
        return out

    @property
    def z_chunk(self) -> int:
        """Rows per stored chunk along z (reads in these units waste nothing)."""
        if self._zarr is not None:
            return int(self._zarr.chunks[1])
        return int(self.data.chunks[1][0])

    def read_rows(self, step: int, z0: int, z1: int, out: np.ndarray) -> None:
        """Read z rows [z0, z1) of one step into `out` (z1 - z0, Y, X)."""
        if self._zarr is not None:
            read_rows(self.path, self._zarr, int(step), z0, z1, out)
        else:
            out[...] = self.step_rows(int(step), z0, z1)

    def step_rows(self, step: int, z0: int, z1: int) -> np.ndarray:
        """Rows [z0, z1) of one step of a series in memory: a view of `host` where there is
        one, else computed through dask."""
        if self.host is not None:
            return self.host[step, z0:z1]
        return np.asarray(self.data[step, z0:z1].compute())

    def read_region(self, steps: slice, z: slice, y: slice, x: slice) -> np.ndarray:
        """Raw values of a run of steps over one (z, y, x) sub-block: (steps, z, y, x).

        A zarr store is read for that block alone: zarr decodes only the chunks it touches,
        through the damage checks (a damaged chunk raises StoreCorruptError).
        """
        sel = (steps, z, y, x)
        if self._zarr is None:
            return np.asarray(self.data[sel].compute())
        return checked_read(self.path, self._zarr, lambda: self._zarr.get_basic_selection(sel), sel)

    def check_unchanged(self) -> None:
        """Raise StoreChangedError when the store on disk no longer has this series' shape, or
        its statistics changed (replaced by another of that shape: `--overwrite`; its old
        statistics would have coloured the new values).

        Cheap when nothing changed: only the array's metadata file is stat'ed.
        """
        if self.path is None or self._zarr is None:
            return
        try:
            stamp = metadata_stamp(self.path, self._zarr)
        except OSError:
            stamp = -1
        if stamp == self._stamp:
            return
        shape = stored_shape(self.path, self._zarr)
        if shape != self.shape:
            now = "is gone" if shape is None else f"now has shape {shape}"
            raise StoreChangedError(
                f"store {str(self.path)!r} changed underneath: opened with shape {self.shape}, "
                f"{now}; open it again to see the new steps"
            )
        stats = stored_stats(self.path)
        kept = (self._root or self).stats  # (a level's own per step: level 0's are stored)
        if stats is not None and stats != dataclasses.astuple(kept):
            raise StoreChangedError(
                f"store {str(self.path)!r} changed underneath: replaced by other values of its "
                "shape; open it again to see them"
            )
        self._stamp = stamp

    def normalized(
        self,
        steps: Sequence[int],
        z0: int = 0,
        z1: int | None = None,
        value_range: tuple[float, float] | None = None,
    ) -> np.ndarray:
        """u = clip((v - vmin) / (vmax - vmin), 0, 1) as float32 (W, z1 - z0, Y, X)."""
        lo, hi = value_range if value_range is not None else (self.vmin, self.vmax)
        return normalize(self.read(steps, z0, z1), lo, hi)

    # -- construction --------------------------------------------------------------------
    @classmethod
    def from_array(
        cls,
        array: object,
        spacing: Sequence[float] | None = None,
        times: Sequence | None = None,
        source: str = "array",
        resample: str | None = None,
        time_unit: str | None = None,
    ) -> TimeSeries:
        """Wrap a numpy or dask array (T, Z, Y, X) with voxel `spacing` (dx, dy, dz), x first.

        An xarray DataArray with a time dimension has its dimensions mapped by name, spacing
        and time labels from its coordinates. No copy is made; statistics are computed in one
        pass. `spacing` is x first although the array is (T, Z, Y, X): a simulation's
        ``[dx, dy, dz]`` goes in as it is.

        A DataArray coordinate that is not uniformly spaced is refused, or with
        ``resample="uniform"`` interpolated lazily onto uniform spacing (noted in `meta`).
        `time_unit` ('s', 'ms', 'days') is the unit of numeric `times`, written after them by
        legends, captions, the viewer and probe plots.
        """
        return cls(**array_fields(array, spacing, times, source, resample, time_unit))

    def steps(self) -> Steps:
        """This series as a reader's unwritten steps (each step computed as it is read)."""
        return Steps(
            read=lambda: (np.asarray(self.data[t].compute()) for t in range(self.n_steps)),
            n_steps=self.n_steps,
            volume_shape=self.volume_shape,
            dtype=self.dtype,
            spacing=self.spacing,
            source=self.source,
            times=list(self.times),
            attrs={
                k: v for k, v in self.meta.items() if k in ("quantity", "components", "time_unit")
            },
        )

    def save(self, path: str | os.PathLike, overwrite: bool = False, progress: bool = False):
        """Write this series as a chronocl store; returns the opened store."""
        steps = self.steps()
        write_store(path, steps.read(), **steps.written(), overwrite=overwrite, progress=progress)
        return open_store(path)

    def _repr_html_(self) -> str | None:
        """A notebook's summary with a small picture, read cheaply (`chronocl.data.repr_html`)."""
        from chronocl.data.repr_html import safe, series_html

        return safe(series_html, self)

    def describe(self) -> dict:
        """A summary for `chronocl info` and the demo."""
        t, z, y, x = self.shape
        d = {
            "path": str(self.path) if self.path else self.meta.get("url"),
            "source": self.source,
            "dims (x, y, z)": [x, y, z],
            "shape (T, Z, Y, X)": [t, z, y, x],
            "dtype": str(self.dtype),
            "value range": [self.vmin, self.vmax],
            "steps": t,
            "time labels": f"{self.times[0]} .. {self.times[-1]}"
            + (f" {self.time_unit}" if self.time_unit else ""),
            "spacing (x, y, z)": list(self.spacing),
            "chunks": list(self.data.chunksize),
            "size in memory": human_size(t * z * y * x * self.dtype.itemsize),
            "levels": describe_levels(self.volume_shape, self.n_levels),
        }
        if self.level_index:
            d["level"] = self.level_index
        for key in ("variable", "quantity", "components", "resampled"):
            if key in self.meta:
                d[key] = self.meta[key]
        if len(self.variables) > 1:
            d["variables"] = (
                f"{', '.join(self.variables)} (this is {self.meta.get('variable')}; "
                "choose with --variables or .variable(name))"
            )
        if self.path is not None:
            d["size on disk"] = human_size(disk_usage(self.path))
        return d


def open_store(path: str | os.PathLike) -> TimeSeries:
    """Open a chronocl store (zarr v3 or v2), or a bare (T, Z, Y, X) zarr array."""
    stored = open_array(Path(path))
    return from_stored(stored).stored_in(stored.path, stored.array)


def from_stored(stored, source: str | None = None, meta: dict | None = None) -> TimeSeries:
    """The series of an opened store (`open_array`'s, local or remote), named `source` with
    `meta` where given; a bare array's statistics computed in one dask pass."""
    source = stored.source if source is None else source
    if stored.stats is None:
        return TimeSeries.from_array(stored.data, source=source)
    meta = stored.meta if meta is None else meta
    spacing, times = stored.spacing, stored.times
    return TimeSeries(stored.data, stored.stats, spacing, times, source=source, meta=meta)
