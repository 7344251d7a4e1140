"""TimeSeries: a time-varying volume (T, Z, Y, X) over a zarr store, read lazily through dask.

A series opens from a chronocl store (zarr v3 written by `chronocl.data.writer`, v2 read), whose
attribute ``chronocl`` holds its statistics, spacing and time labels; from a bare zarr array (v2
or v3) without them, whose statistics are then computed in one dask pass; or from any array
(`TimeSeries.from_array`). Reads of a zarr-backed series go to zarr directly, decoding straight
into the caller's buffer, and through `chronocl.data.integrity` so damage is never read as zeros.
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
from zarr.buffer import default_buffer_prototype

from chronocl.core.errors import (
    InvalidDataError,
    StoreChangedError,
    StoreFormatError,
    UnknownNameError,
)
from chronocl.core.memory import aligned_empty
from chronocl.core.values import normalize
from chronocl.data.formats.contract import Steps
from chronocl.data.integrity import CheckedArray, CheckedStore, checked_read, damaged
from chronocl.data.labelled import dataarray_layout
from chronocl.data.metadata import (
    FORMAT,
    SeriesStats,
    check_dtype,
    check_shape,
    checked_attrs,
    parse_spacing,
    parse_times,
    stats_from_steps,
    unreadable_metadata,
)
from chronocl.data.pyramid import check_pool, count_levels, describe_levels, level_parts
from chronocl.data.stores import require_store
from chronocl.data.writer import EXTRA_KEYS, VARIABLES, write_store

# Steps read per zarr call by default, whose chunks zarr decodes concurrently (at most 10 at
# once, zarr's async.concurrency). The streaming plan chooses fewer when the budget is tight.
STEPS_PER_READ = 8


@dataclass
class TimeSeries:
    """A (T, Z, Y, X) series with its statistics, voxel spacing and time labels.

    `spacing` is (dx, dy, dz), x first, like every per-axis triple of the API (`dims`, probe
    points and boxes); only array shapes (`shape`, `volume_shape`) follow the array's (T, Z,
    Y, X). `level_index` is 0 for the series itself, n for its coarse level n (`level(n)`).
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
    _levels: dict = field(default_factory=dict, repr=False)
    # Coarse levels pooled on the fly (in-memory series, OME-Zarr images read in place) rather
    # than read from a chronocl store's `levels`.
    _lazy_levels: bool = field(default=False, repr=False)
    # What a store records beside the data (`writer.EXTRA_KEYS`): the variable's name and the
    # store's variables, a derived quantity and its components, resampling notes.
    meta: dict = field(default_factory=dict, repr=False)
    # Opens another variable of the same source by name where it is not a chronocl store's
    # (an OME-Zarr image's channels, read in place).
    _variable: Callable[[str], TimeSeries] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.times:
            self.times = tuple(range(self.n_steps))
        if self.path is not None and self._zarr is not None:
            meta = _metadata_file(self.path, self._zarr)
            self._stamp = meta.stat().st_mtime_ns if meta is not None else None

    def stored_in(self, path: Path, arr: zarr.Array | None = None) -> TimeSeries:
        """Note that this series is read from the store at `path`; returns the series.

        `arr`, the zarr array of that store which `data` wraps step for step, makes reads go
        to zarr directly and lets `check_unchanged` tell when the store changes.
        """
        self.path, self._zarr = path, arr
        self.__post_init__()
        return self

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
        if self._variable is not None:
            return self._variable(name)
        if root is None:
            return self
        return open_store(root if name == names[0] else root / VARIABLES / name)

    # -- coarse levels (chronocl.data.pyramid) -------------------------------------------------
    @property
    def n_levels(self) -> int:
        """1 + the coarse levels: stored ones, or (in memory) those `level_shapes` gives."""
        return count_levels(self._root or self)

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
            root._levels[n, pool] = dataclasses.replace(
                root, **level_parts(root, n, pool), level_index=int(n), _root=root, _levels={}
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
        per_call: int = STEPS_PER_READ,
    ) -> np.ndarray:
        """Raw values of z rows [z0, z1) of the given steps as an xytz brick (z1 - z0, W, Y, X).

        `out`, if given, is filled and returned (a C-contiguous array of that shape and dtype).
        A zarr store is read up to `per_call` evenly spaced steps per call, decoding straight
        into the brick: zarr fetches and decodes the chunks of one call concurrently, where
        one call per step would decode them one at a time.
        """
        z1 = self.shape[1] if z1 is None else z1
        if out is None:
            out = aligned_empty((z1 - z0, len(steps), *self.shape[2:]), self.dtype)
        if self._zarr is None:
            for i, s in enumerate(steps):
                out[:, i] = self.data[int(s), z0:z1].compute()
            return out
        wrap = default_buffer_prototype().nd_buffer.from_numpy_array
        for i0, i1, run in step_runs(steps, per_call):
            # (rows, n, Y, X) of the brick seen as (n, rows, Y, X), the store's order.
            view = out[:, i0:i1].transpose(1, 0, 2, 3)
            selection = (run, slice(z0, z1))
            checked_read(
                self.path,
                self._zarr,
                lambda sel=selection, v=view: self._zarr.get_basic_selection(sel, out=wrap(v)),
                selection,
            )
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
            sel = (int(step), slice(z0, z1))
            out[...] = checked_read(self.path, self._zarr, lambda: self._zarr[sel], sel)
        else:
            out[...] = self.data[int(step), z0:z1].compute()

    def read_region(self, steps: slice, z: slice, y: slice, x: slice) -> np.ndarray:
        """Raw values of a run of steps over one (z, y, x) sub-block: (steps, z, y, x).

        A zarr store is read for that block alone: zarr decodes only the chunks it touches,
        through the damage checks (a damaged chunk raises StoreCorruptError).
        """
        sel = (steps, z, y, x)
        if self._zarr is None:
            return np.asarray(self.data[sel].compute())
        return checked_read(self.path, self._zarr, lambda: self._zarr.get_basic_selection(sel), sel)

    def probe(
        self,
        x: int | None = None,
        y: int | None = None,
        z: int | None = None,
        *,
        region: object = None,
        progress: bool = False,
    ):
        """v(t) at voxel (x, y, z), or the mean, min and max per step over the box `region`
        ('x0:x1,y0:y1,z0:z1' or three slices), with the time labels: a TimeCurve
        (`chronocl.data.probe`)."""
        from chronocl.data.probe import probe

        return probe(self, x, y, z, region=region, progress=progress)

    def check_unchanged(self) -> None:
        """Raise StoreChangedError when the store on disk no longer has this series' shape.

        Cheap when nothing changed: only the array's metadata file is stat'ed.
        """
        if self.path is None or self._zarr is None:
            return
        meta = _metadata_file(self.path, self._zarr)
        try:
            stamp = meta.stat().st_mtime_ns if meta is not None else None
        except OSError:
            stamp = -1
        if stamp == self._stamp:
            return
        try:
            node = zarr.open(store=str(self.path), mode="r")
            inner = self._zarr.path  # "data" in a chronocl store, "" for a bare array
            shape = tuple((node[inner] if isinstance(node, zarr.Group) else node).shape)
        except Exception:
            shape = None
        if shape != self.shape:
            now = "is gone" if shape is None else f"now has shape {shape}"
            raise StoreChangedError(
                f"store {str(self.path)!r} changed underneath: opened with shape {self.shape}, "
                f"{now}; open it again to see the new steps"
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
    ) -> TimeSeries:
        """Wrap a numpy or dask array (T, Z, Y, X) with voxel `spacing` (dx, dy, dz), x first.

        An xarray DataArray with a time dimension has its dimensions mapped by name, spacing
        and time labels from its coordinates. No copy is made; statistics are computed in one
        pass. `spacing` is x first although the array is (T, Z, Y, X): a simulation's
        ``[dx, dy, dz]`` goes in as it is.

        A DataArray coordinate that is not uniformly spaced is refused, or with
        ``resample="uniform"`` interpolated lazily onto uniform spacing (noted in `meta`).
        """
        meta: dict = {}
        if type(array).__module__.startswith("xarray"):
            array, coord_spacing, coord_times, notes = dataarray_layout(array, resample=resample)
            spacing = coord_spacing if spacing is None else spacing
            times = coord_times if times is None else times
            if notes:
                meta["resampled"] = notes
        spacing = (1.0, 1.0, 1.0) if spacing is None else spacing
        if not isinstance(array, da.Array):
            try:
                array = np.asarray(array)
            except (ValueError, TypeError) as exc:
                raise InvalidDataError(
                    f"{source} is not a rectangular array ({exc}); pass a (T, Z, Y, X) array"
                ) from None
        check_shape(array.shape, "array")
        check_dtype(array.dtype)
        arr = array if isinstance(array, da.Array) else da.from_array(array)
        finite = da.isfinite(arr).all() if arr.dtype.kind == "f" else da.from_array(True)
        smin, smax, smean, ok = da.compute(
            arr.min(axis=(1, 2, 3)), arr.max(axis=(1, 2, 3)), arr.mean(axis=(1, 2, 3)), finite
        )
        if not ok:
            bad = int(np.argmax(~np.isfinite(smin + smax)))
            raise InvalidDataError(
                f"time step {bad} of {source} holds NaN or infinite values; "
                "replace them first (e.g. numpy.nan_to_num) so the value range is defined"
            )
        stats = stats_from_steps(smin, smax, smean)
        return cls(
            data=arr,
            stats=stats,
            spacing=parse_spacing(spacing),
            times=parse_times(times, arr.shape[0]),
            source=source,
            meta=meta,
        )

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
            attrs={k: v for k, v in self.meta.items() if k in ("quantity", "components")},
        )

    def save(self, path: str | os.PathLike, overwrite: bool = False, progress: bool = False):
        """Write this series as a chronocl store; returns the opened store."""
        steps = self.steps()
        write_store(path, steps.read(), **steps.written(), overwrite=overwrite, progress=progress)
        return open_store(path)

    def describe(self) -> dict:
        """A summary for `chronocl info` and the demo."""
        t, z, y, x = self.shape
        d = {
            "path": str(self.path) if self.path else None,
            "source": self.source,
            "dims (x, y, z)": [x, y, z],
            "shape (T, Z, Y, X)": [t, z, y, x],
            "dtype": str(self.dtype),
            "value range": [self.vmin, self.vmax],
            "steps": t,
            "time labels": f"{self.times[0]} .. {self.times[-1]}",
            "spacing (x, y, z)": list(self.spacing),
            "chunks": list(self.data.chunksize),
            "size in memory": _human(t * z * y * x * self.dtype.itemsize),
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
            d["size on disk"] = _human(_disk_usage(self.path))
        return d


def open_store(path: str | os.PathLike) -> TimeSeries:
    """Open a chronocl store (zarr v3 or v2), or a bare (T, Z, Y, X) zarr array."""
    p = Path(path)
    require_store(p)
    store = CheckedStore(p)
    try:
        node = zarr.open(store=store, mode="r")
        has_data = isinstance(node, zarr.Group) and "data" in node
        arr = node["data"] if has_data else node
    except Exception as exc:  # zarr raises several kinds for a non-store folder
        bad = unreadable_metadata(p)
        if bad is not None:
            raise damaged(p, f"its metadata file {bad} cannot be read") from None
        raise StoreFormatError(
            f"{str(p)!r} is not a zarr store ({type(exc).__name__}); "
            "ingest your data with 'chronocl ingest'"
        ) from None
    if isinstance(arr, zarr.Group):
        raise StoreFormatError(
            f"zarr group {str(p)!r} has no array 'data'; "
            "it is not a chronocl series (is it a chronovolume?)"
        )
    if not has_data:
        store.arrays = ("",)
    attrs = dict(node.attrs).get("chronocl", {})
    check_shape(arr.shape, str(p))
    check_dtype(arr.dtype)
    lazy = da.from_array(CheckedArray(p, arr), chunks=arr.chunks, name=f"chronocl-{p}-{id(arr)}")
    if isinstance(attrs, dict) and attrs.get("format") == FORMAT:
        stats, spacing, times = checked_attrs(p, arr, attrs)
        if attrs.get("chunks") == "complete":
            store.complete = True
        else:  # written before stores kept empty chunks: a step may lack all-fill chunks
            fill = float(arr.fill_value)
            store.may_miss = frozenset(
                t for t in range(arr.shape[0]) if stats.step_min[t] <= fill <= stats.step_max[t]
            )
        return TimeSeries(
            data=lazy,
            stats=stats,
            spacing=spacing,
            times=times,
            source=str(attrs.get("source", p)),
            path=p,
            _zarr=arr,
            meta={k: attrs[k] for k in EXTRA_KEYS if k in attrs},
        )
    return TimeSeries.from_array(lazy, source=str(p)).stored_in(p, arr)


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


def _metadata_file(path: Path, arr: zarr.Array) -> Path | None:
    """The file holding an array's shape in a local store (zarr v3 or v2), if there is one."""
    folder = Path(path) / arr.path if arr.path else Path(path)
    for name in ("zarr.json", ".zarray"):
        if (folder / name).is_file():
            return folder / name
    return None


def _disk_usage(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file())


def _human(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if n < 1024 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} B"
