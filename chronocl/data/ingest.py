"""Ingest time steps into a chronocl store: one raw file per step, or a (T, Z, Y, X) .npy.

Raw files are headerless, x fastest then y then z, as the classic vortex and
jet data sets are shipped. Files come as globs or a list and are sorted
naturally (step2 before step10). Everything is checked before the first byte
is written (sizes, existence), statistics are computed while writing, and the
store is written to a temporary sibling that is renamed only when complete.
"""

from __future__ import annotations

import glob
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from natsort import natsorted

from chronocl.core.errors import (
    InputNotFoundError,
    InvalidDataError,
    InvalidParameterError,
    UnknownNameError,
)
from chronocl.core.paths import GLOB_CHARS
from chronocl.data.series import SUPPORTED_DTYPES, TimeSeries, write_series

ENDIANS = ("little", "big")


def expand_inputs(inputs: Sequence[str | os.PathLike]) -> list[Path]:
    """Expand globs, check every file exists, and sort naturally."""
    if not inputs:
        raise InputNotFoundError("no input files given; pass files or a glob such as 'v_*.raw'")
    files: list[str] = []
    for item in inputs:
        text = str(item)
        if GLOB_CHARS & set(text):
            matched = glob.glob(text)
            if not matched:
                raise InputNotFoundError(f"no files match {text!r}; check the pattern and folder")
            files.extend(matched)
        elif not os.path.exists(text):
            raise InputNotFoundError(f"input file {text!r} does not exist")
        elif os.path.isdir(text):
            raise InvalidParameterError(
                f"input {text!r} is a folder; give the files inside it, e.g. '{text}/*.raw'"
            )
        else:
            files.append(text)
    return [Path(f) for f in natsorted(dict.fromkeys(files))]


def ingest_raw(
    inputs: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    dims: Sequence[int],
    dtype: str = "float32",
    endian: str = "little",
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    times: Sequence | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> TimeSeries:
    """One raw file per time step; `dims` is (NX, NY, NZ), `spacing` is (dz, dy, dx)."""
    if dtype not in SUPPORTED_DTYPES:
        raise UnknownNameError(
            f"unknown dtype {dtype!r}; choose one of {', '.join(SUPPORTED_DTYPES)}"
        )
    if endian not in ENDIANS:
        raise UnknownNameError(f"unknown endianness {endian!r}; choose little or big")
    if len(dims) != 3 or any(int(n) < 1 for n in dims):
        raise InvalidParameterError(
            f"dims {list(dims)} must be three positive sizes NX NY NZ (e.g. --dims 128 128 128)"
        )
    nx, ny, nz = (int(n) for n in dims)
    files = expand_inputs(inputs)
    file_dtype = np.dtype(dtype).newbyteorder("<" if endian == "little" else ">")
    expected = nx * ny * nz * file_dtype.itemsize
    sizes = {f: f.stat().st_size for f in files}
    distinct = sorted(set(sizes.values()))
    if len(distinct) > 1:
        a = next(f for f in files if sizes[f] == distinct[0])
        b = next(f for f in files if sizes[f] == distinct[-1])
        raise InvalidDataError(
            f"input files differ in size ({a.name}: {sizes[a]} bytes, {b.name}: {sizes[b]} "
            "bytes); every time step must have the same dims"
        )
    if distinct[0] != expected:
        raise InvalidDataError(
            f"{files[0].name} has {distinct[0]} bytes but --dims {nx} {ny} {nz} --dtype {dtype} "
            f"needs {expected}; check --dims and --dtype"
        )

    def steps() -> Iterator[np.ndarray]:
        for f in files:
            raw = np.fromfile(f, dtype=file_dtype, count=nx * ny * nz)
            yield raw.reshape(nz, ny, nx).astype(np.dtype(dtype), copy=False)

    return write_series(
        out,
        steps(),
        n_steps=len(files),
        volume_shape=(nz, ny, nx),
        dtype=dtype,
        spacing=spacing,
        times=times,
        source=f"raw: {files[0].parent}/{files[0].name} .. {files[-1].name} ({len(files)} files)",
        overwrite=overwrite,
        progress=progress,
        nan_fill=nan_fill,
        labels=[f"{f.name} (step {t})" for t, f in enumerate(files)],
    )


def ingest_npy(
    path: str | os.PathLike,
    out: str | os.PathLike,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    times: Sequence | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> TimeSeries:
    """A .npy of shape (T, Z, Y, X), read memory-mapped one step at a time."""
    p = Path(path)
    if not p.is_file():
        raise InputNotFoundError(f"input file {str(p)!r} does not exist")
    try:
        arr = np.load(p, mmap_mode="r", allow_pickle=False)
    except ValueError as exc:
        raise InvalidDataError(f"{p.name} is not a readable .npy file ({exc})") from None
    if arr.ndim != 4:
        raise InvalidDataError(
            f"{p.name} has shape {arr.shape}; a .npy series must be 4D (T, Z, Y, X)"
        )
    if arr.shape[0] == 0:
        raise InvalidDataError(f"{p.name} has zero time steps; a series needs at least one")
    return write_series(
        out,
        (np.asarray(arr[t]) for t in range(arr.shape[0])),
        n_steps=arr.shape[0],
        volume_shape=arr.shape[1:],
        dtype=arr.dtype.newbyteorder("="),
        spacing=spacing,
        times=times,
        source=f"npy: {p}",
        overwrite=overwrite,
        progress=progress,
        nan_fill=nan_fill,
    )


FORMATS = ("auto", "raw", "npy", "netcdf", "tiff", "omezarr")
_SUFFIXES = {
    ".npy": "npy",
    ".nc": "netcdf",
    ".nc4": "netcdf",
    ".cdf": "netcdf",
    ".netcdf": "netcdf",
    ".h5": "netcdf",
    ".hdf5": "netcdf",
    ".he5": "netcdf",
    ".tif": "tiff",
    ".tiff": "tiff",
}
# Options that only some readers take, and the formats they belong to.
_ONLY_FOR = {
    "dims": ("raw",),
    "dtype": ("raw",),
    "endian": ("raw",),
    "var": ("netcdf",),
    "time_dim": ("netcdf",),
    "dims_order": ("netcdf",),
    "channel": ("omezarr",),
    "level": ("omezarr",),
    "spacing": ("raw", "npy", "tiff"),  # NetCDF coordinates and OME-Zarr scales carry their own
}
_DEFAULTS = {"dtype": "float32", "endian": "little", "channel": 0, "level": 0}


def detect_format(inputs: Sequence[str | os.PathLike]) -> str:
    """The reader for these inputs, from the file type (a folder: OME-Zarr)."""
    first = Path(str(inputs[0]))
    if first.is_dir():
        from chronocl.data.formats.omezarr import is_omezarr

        if is_omezarr(first):
            return "omezarr"
        raise InvalidParameterError(
            f"{first} is a folder but not an OME-Zarr image; give files, or --format"
        )
    name = first.name.lower()
    if name.endswith(".ome.tif") or name.endswith(".ome.tiff"):
        return "tiff"
    return _SUFFIXES.get(first.suffix.lower(), "raw")


def ingest(
    inputs: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    fmt: str = "auto",
    **options: object,
) -> TimeSeries:
    """Ingest with the reader for `fmt` (``auto``: by file type; raw files need dims=)."""
    from chronocl.core.paths import check_apart

    check_apart(out, inputs)  # never onto, into or around an input
    if fmt not in FORMATS:
        raise UnknownNameError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if not inputs:
        raise InputNotFoundError("no input files given; pass files or a glob such as 'v_*.raw'")
    if fmt == "auto":
        fmt = detect_format(inputs)
    for key, formats in _ONLY_FOR.items():
        value = options.pop(key, None) if fmt not in formats else options.get(key)
        if fmt not in formats and value not in (None, _DEFAULTS.get(key)):
            flag = "--" + key.replace("_", "-")
            raise InvalidParameterError(f"{flag} applies to {'/'.join(formats)} input, not {fmt}")
    single = fmt in ("npy", "netcdf", "omezarr")
    if single and len(inputs) != 1:
        raise InvalidParameterError(f"{fmt} input is one file; got {len(inputs)}")
    if fmt in ("raw", "npy") and options.get("spacing") is None:
        options["spacing"] = (1.0, 1.0, 1.0)
    if fmt == "npy":
        return ingest_npy(inputs[0], out, **options)  # type: ignore[arg-type]
    if fmt == "netcdf":
        from chronocl.data.formats.netcdf import ingest_netcdf

        return ingest_netcdf(inputs[0], out, **options)  # type: ignore[arg-type]
    if fmt == "tiff":
        from chronocl.data.formats.tiff import ingest_tiff

        return ingest_tiff(inputs, out, **options)  # type: ignore[arg-type]
    if fmt == "omezarr":
        from chronocl.data.formats.omezarr import open_omezarr

        channel, level = options.pop("channel", 0), options.pop("level", 0)
        options.pop("nan_fill", None)
        series = open_omezarr(inputs[0], channel=channel, level=level)  # type: ignore[arg-type]
        return series.save(out, **options)  # type: ignore[arg-type]
    if options.get("dims") is None:
        raise InvalidParameterError(
            "raw input needs --dims NX NY NZ (and --dtype, --endian if not float32 little-endian)"
        )
    return ingest_raw(inputs, out, **options)  # type: ignore[arg-type]
