"""TimeSeries: a time-varying volume (T, Z, Y, X) over a zarr store, read lazily through dask.

Store layout (zarr v3 written, v2 read): a group whose array ``data`` is
(T, Z, Y, X), chunked (1, zc, Y, X) so one step is one small set of chunks,
and whose attribute ``chronocl`` holds the global value range, per-step
min/max/mean, voxel spacing, time labels and a source description. A bare
zarr array (v2 or v3) without those attributes opens too; its statistics are
then computed in one dask pass.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import dask.array as da
import numpy as np
import zarr

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    InvalidDataError,
    InvalidParameterError,
    StoreChangedError,
    StoreFormatError,
)
from chronocl.core.memory import aligned_empty
from chronocl.core.progress import track
from chronocl.core.values import normalize
from chronocl.data.integrity import CheckedArray, CheckedStore, checked_read, damaged

FORMAT = "chronocl.series"
# Steps read per zarr call by default, whose chunks zarr decodes concurrently (at most 10 at
# once, zarr's async.concurrency). The streaming plan chooses fewer when the budget is tight.
STEPS_PER_READ = 8
CHUNK_BYTES = 16 * 2**20
SUPPORTED_DTYPES = ("uint8", "uint16", "int16", "float32", "float64")


@dataclass(frozen=True)
class SeriesStats:
    """Statistics gathered while writing: global range and per-step min/max/mean."""

    vmin: float
    vmax: float
    step_min: tuple[float, ...]
    step_max: tuple[float, ...]
    step_mean: tuple[float, ...]


@dataclass
class TimeSeries:
    """A (T, Z, Y, X) series with its statistics, spacing (dz, dy, dx) and time labels."""

    data: da.Array
    stats: SeriesStats
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    times: tuple = ()
    source: str = ""
    path: Path | None = None
    _zarr: zarr.Array | None = field(default=None, repr=False)
    _stamp: int | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.times:
            self.times = tuple(range(self.n_steps))
        if self.path is not None and self._zarr is not None:
            meta = _metadata_file(self.path, self._zarr)
            self._stamp = meta.stat().st_mtime_ns if meta is not None else None

    # -- shape ---------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int, int]:
        return tuple(int(n) for n in self.data.shape)  # type: ignore[return-value]

    @property
    def n_steps(self) -> int:
        return self.shape[0]

    @property
    def volume_shape(self) -> tuple[int, int, int]:
        """(Z, Y, X) of one step."""
        return self.shape[1:]  # type: ignore[return-value]

    @property
    def dtype(self) -> np.dtype:
        return self.data.dtype

    @property
    def vmin(self) -> float:
        return self.stats.vmin

    @property
    def vmax(self) -> float:
        return self.stats.vmax

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
        from zarr.core.buffer import default_buffer_prototype

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
            shape = tuple((node["data"] if isinstance(node, zarr.Group) else node).shape)
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
    ) -> TimeSeries:
        """Wrap a numpy or dask array (T, Z, Y, X), or an xarray DataArray with a time
        dimension (dimensions mapped by name, spacing and time labels from its coordinates);
        no copy is made. Statistics are computed in one pass."""
        if type(array).__module__.startswith("xarray"):
            from chronocl.data.formats.netcdf import dataarray_layout

            array, coord_spacing, coord_times = dataarray_layout(array)
            spacing = coord_spacing if spacing is None else spacing
            times = coord_times if times is None else times
            array = array.data  # numpy (a view) or dask
        spacing = (1.0, 1.0, 1.0) if spacing is None else spacing
        if not isinstance(array, da.Array):
            try:
                array = np.asarray(array)
            except (ValueError, TypeError) as exc:
                raise InvalidDataError(
                    f"{source} is not a rectangular array ({exc}); pass a (T, Z, Y, X) array"
                ) from None
        _check_shape(array.shape, "array")
        _check_dtype(array.dtype)
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
        stats = _stats_from_steps(smin, smax, smean)
        return cls(
            data=arr,
            stats=stats,
            spacing=parse_spacing(spacing),
            times=_parse_times(times, arr.shape[0]),
            source=source,
        )

    def save(self, path: str | os.PathLike, overwrite: bool = False, progress: bool = False):
        """Write this series as a chronocl store; returns the opened store."""
        steps = (np.asarray(self.data[t].compute()) for t in range(self.n_steps))
        return write_series(
            path,
            steps,
            n_steps=self.n_steps,
            volume_shape=self.volume_shape,
            dtype=self.dtype,
            spacing=self.spacing,
            times=self.times,
            source=self.source,
            overwrite=overwrite,
            progress=progress,
        )

    def describe(self) -> dict:
        """A summary for `chronocl info` and the demo."""
        t, z, y, x = self.shape
        d = {
            "path": str(self.path) if self.path else None,
            "source": self.source,
            "shape (T, Z, Y, X)": [t, z, y, x],
            "dtype": str(self.dtype),
            "value range": [self.vmin, self.vmax],
            "steps": t,
            "time labels": f"{self.times[0]} .. {self.times[-1]}",
            "spacing (x, y, z)": [self.spacing[2], self.spacing[1], self.spacing[0]],
            "chunks": list(self.data.chunksize),
            "size in memory": _human(t * z * y * x * self.dtype.itemsize),
        }
        if self.path is not None:
            d["size on disk"] = _human(_disk_usage(self.path))
        return d


def open_series(path: str | os.PathLike) -> TimeSeries:
    """Open a chronocl store (zarr v3 or v2), or a bare (T, Z, Y, X) zarr array."""
    p = Path(path)
    if not p.exists():
        raise InputNotFoundError(
            f"store {str(p)!r} does not exist; create one with 'chronocl ingest' or "
            "'chronocl generate'"
        )
    from chronocl.data.formats.omezarr import is_omezarr, open_omezarr

    if is_omezarr(p):  # opened in place: channel 0, full resolution
        return open_omezarr(p)
    store = CheckedStore(p)
    try:
        node = zarr.open(store=store, mode="r")
        has_data = isinstance(node, zarr.Group) and "data" in node
        arr = node["data"] if has_data else node
    except Exception as exc:  # zarr raises several kinds for a non-store folder
        bad = _unreadable_metadata(p)
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
    _check_shape(arr.shape, str(p))
    _check_dtype(arr.dtype)
    lazy = da.from_array(CheckedArray(p, arr), chunks=arr.chunks, name=f"chronocl-{p}-{id(arr)}")
    if isinstance(attrs, dict) and attrs.get("format") == FORMAT:
        stats, spacing, times = _checked_attrs(p, arr, attrs)
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
        )
    series = TimeSeries.from_array(lazy, source=str(p))
    series.path, series._zarr = p, arr
    series.__post_init__()  # records the metadata stamp that check_unchanged compares with
    return series


def _unreadable_metadata(path: Path) -> str | None:
    """The first zarr metadata file under `path` that is not valid JSON, relative to it."""
    import json

    for name in ("zarr.json", ".zgroup", ".zarray", ".zattrs"):
        for f in (path / name, path / "data" / name):
            if not f.is_file():
                continue
            try:
                json.loads(f.read_bytes())
            except (ValueError, RecursionError):
                return str(f.relative_to(path))
    return None


def _checked_attrs(path: Path, arr, attrs: dict) -> tuple[SeriesStats, tuple, tuple]:
    """The statistics, spacing and time labels of a chronocl store, checked against its array.

    Raises StoreCorruptError when they are missing, malformed or disagree with the array.
    """
    t = arr.shape[0]

    def number(value: object, what: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise damaged(path, f"its {what} is {value!r}, not a number")
        if not math.isfinite(value):
            raise damaged(path, f"its {what} is {value}, not a finite number")
        return float(value)

    def numbers(key: str) -> tuple[float, ...]:
        values = attrs.get(key)
        if not isinstance(values, list):
            raise damaged(path, f"its statistics lack the list {key!r}")
        if len(values) != t:
            raise damaged(
                path, f"it has {t} time steps but {len(values)} entries in its {key} statistics"
            )
        return tuple(number(v, f"{key}[{i}]") for i, v in enumerate(values))

    for key in ("vmin", "vmax"):
        if key not in attrs:
            raise damaged(path, f"its statistics lack {key!r}")
    vmin, vmax = number(attrs["vmin"], "vmin"), number(attrs["vmax"], "vmax")
    smin, smax, smean = numbers("step_min"), numbers("step_max"), numbers("step_mean")
    if vmin > vmax:
        raise damaged(path, f"its value range [{vmin}, {vmax}] is inverted")
    if vmin != min(smin) or vmax != max(smax):
        raise damaged(
            path,
            f"its value range [{vmin}, {vmax}] disagrees with its per-step statistics "
            f"[{min(smin)}, {max(smax)}]",
        )
    for i, (lo, mean, hi) in enumerate(zip(smin, smean, smax, strict=True)):
        if not lo <= hi or not lo - 1e-6 * abs(lo) <= mean <= hi + 1e-6 * abs(hi):
            raise damaged(path, f"the statistics of step {i} are inconsistent")
    chunks = tuple(arr.chunks)
    if chunks[0] != 1 or chunks[2:] != tuple(arr.shape[2:]):
        raise damaged(
            path,
            f"its chunk shape {chunks} is not one step of whole (Y, X) planes "
            f"(1, zc, {arr.shape[2]}, {arr.shape[3]}) as chronocl writes",
        )
    sp = attrs.get("spacing", {})
    try:
        spacing = parse_spacing((sp.get("z", 1.0), sp.get("y", 1.0), sp.get("x", 1.0)))
    except (ChronoclError, AttributeError):
        raise damaged(path, f"its voxel spacing {sp!r} is not three numbers > 0") from None
    times = attrs.get("times", [])
    if not isinstance(times, list) or len(times) not in (0, t):
        n = len(times) if isinstance(times, list) else type(times).__name__
        raise damaged(path, f"it has {t} time steps but {n} time labels")
    stats = SeriesStats(vmin=vmin, vmax=vmax, step_min=smin, step_max=smax, step_mean=smean)
    return stats, spacing, tuple(times)


def write_series(
    path: str | os.PathLike,
    steps: Iterable[np.ndarray],
    *,
    n_steps: int,
    volume_shape: Sequence[int],
    dtype: object,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    times: Sequence | None = None,
    source: str = "",
    overwrite: bool = False,
    progress: bool = False,
    nan_fill: float | None = None,
    labels: Sequence[str] | None = None,
    chunk_bytes: int = CHUNK_BYTES,
    compressor: str = "zstd",
    checksum: bool = True,
) -> TimeSeries:
    """Write steps (each (Z, Y, X)) to a new store atomically, gathering statistics on the way.

    Non-finite values are rejected unless `nan_fill` is given, which replaces them.
    `labels` name each step's origin (e.g. its file) in error messages. Chunks are
    (1, zc, Y, X) of at most `chunk_bytes` (small chunks suit small streaming budgets);
    `compressor` is one of COMPRESSORS; `checksum` adds a crc32c per chunk.
    """
    dt = np.dtype(dtype)
    _check_dtype(dt)
    if nan_fill is not None and not (
        isinstance(nan_fill, int | float | np.number) and math.isfinite(nan_fill)
    ):
        raise InvalidParameterError(
            f"--nan-fill {nan_fill} must be a finite number (it replaces NaN and infinite values)"
        )
    shape = (int(n_steps), *(int(n) for n in volume_shape))
    _check_shape(shape, source or str(path))
    spacing = parse_spacing(spacing)
    times = _parse_times(times, n_steps)
    z, y, x = shape[1:]
    zc = max(1, min(z, int(chunk_bytes) // max(1, y * x * dt.itemsize)))
    codecs = compressors(compressor, checksum)
    smin, smax, smean = [], [], []
    with atomic_directory(path, overwrite) as tmp:
        group = zarr.open_group(store=str(tmp), mode="w", zarr_format=3)
        arr = group.create_array(
            "data",
            shape=shape,
            chunks=(1, zc, y, x),
            dtype=dt,
            compressors=codecs,
            config={"write_empty_chunks": True},  # a missing chunk then always means damage
        )
        count = 0
        for t, step in enumerate(track(steps, n_steps, "writing steps", progress)):
            where = labels[t] if labels else f"time step {t}"
            step = np.asarray(step)
            if t >= n_steps:
                raise InvalidDataError(f"got more than the {n_steps} steps announced")
            if step.shape != shape[1:]:
                raise InvalidDataError(
                    f"{where} has shape {step.shape}, expected {shape[1:]} (Z, Y, X)"
                )
            if dt.kind == "f":
                bad = ~np.isfinite(step)
                n_bad = int(bad.sum())
                if n_bad:
                    if nan_fill is None:
                        raise InvalidDataError(
                            f"{where} has {n_bad} NaN/infinite values; pass --nan-fill VALUE "
                            "(nan_fill=...) to replace them"
                        )
                    step = np.where(bad, dt.type(nan_fill), step)
            step = step.astype(dt, copy=False)
            arr[t] = step
            smin.append(float(step.min()))
            smax.append(float(step.max()))
            smean.append(float(step.mean(dtype=np.float64)))
            count += 1
        if count != n_steps:
            raise InvalidDataError(f"got {count} time steps, expected {n_steps}")
        stats = _stats_from_steps(smin, smax, smean)
        group.attrs["chronocl"] = {
            "format": FORMAT,
            "version": 1,
            "chunks": "complete",
            "vmin": stats.vmin,
            "vmax": stats.vmax,
            "step_min": list(stats.step_min),
            "step_max": list(stats.step_max),
            "step_mean": list(stats.step_mean),
            "spacing": {"x": spacing[2], "y": spacing[1], "z": spacing[0]},
            "times": list(times),
            "source": source,
        }
    return open_series(path)


COMPRESSORS = ("zstd", "blosc-lz4", "none")


def compressors(name: str, checksum: bool = True) -> object:
    """zarr v3 compressors for a name in COMPRESSORS (zstd level 0 is zarr's default).

    With `checksum` a crc32c of every encoded chunk follows the compressor, so a chunk whose
    bytes changed on disk fails to read (StoreCorruptError) instead of decoding to other values.
    """
    from zarr.codecs import BloscCodec, Crc32cCodec, ZstdCodec

    if name not in COMPRESSORS:
        raise InvalidParameterError(
            f"unknown compressor {name!r}; choose one of {', '.join(COMPRESSORS)}"
        )
    chain = {
        "zstd": [ZstdCodec(level=0)],
        "blosc-lz4": [BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")],
        "none": [],
    }[name]
    if checksum:
        chain.append(Crc32cCodec())
    return tuple(chain) or None


def parse_spacing(spacing: Sequence[float]) -> tuple[float, float, float]:
    """Validate a voxel spacing (dz, dy, dx): three finite numbers > 0."""
    try:
        sp = tuple(float(s) for s in spacing)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"spacing {spacing!r} must be three numbers") from None
    if len(sp) != 3 or not all(math.isfinite(s) and s > 0 for s in sp):
        raise InvalidParameterError(
            f"spacing {list(sp)} must be three finite numbers > 0 (one per axis)"
        )
    return sp  # type: ignore[return-value]


def _parse_times(times: Sequence | None, n_steps: int) -> tuple:
    if times is None or len(times) == 0:
        return tuple(range(n_steps))
    if len(times) != n_steps:
        raise InvalidParameterError(
            f"got {len(times)} time labels for {n_steps} steps; give one label per step"
        )
    out = []
    for t in times:
        if isinstance(t, np.generic):
            t = t.item()
        if isinstance(t, float) and not math.isfinite(t):
            raise InvalidParameterError(f"time label {t} is not finite")
        out.append(t if isinstance(t, int | float | str) else str(t))
    return tuple(out)


def _check_shape(shape: Sequence[int], what: str) -> None:
    if len(shape) != 4:
        raise InvalidDataError(
            f"{what} has {len(shape)} dimensions {tuple(shape)}; a series is 4D (T, Z, Y, X)"
        )
    if shape[0] == 0:
        raise InvalidDataError(f"{what} has zero time steps; a series needs at least one")
    if min(shape[1:]) == 0:
        raise InvalidDataError(f"{what} has an empty volume {tuple(shape[1:])} (Z, Y, X)")


def _check_dtype(dtype: np.dtype) -> None:
    if np.dtype(dtype).name not in SUPPORTED_DTYPES:
        raise InvalidDataError(
            f"data type {np.dtype(dtype).name} is not supported; "
            f"use one of {', '.join(SUPPORTED_DTYPES)}"
        )


def _stats_from_steps(smin, smax, smean) -> SeriesStats:
    return SeriesStats(
        vmin=float(np.min(smin)),
        vmax=float(np.max(smax)),
        step_min=tuple(float(v) for v in smin),
        step_max=tuple(float(v) for v in smax),
        step_mean=tuple(float(v) for v in smean),
    )


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
