"""Ingest TIFF stacks into a chronocl store: one 3D (Z, Y, X) file per step, or one 4D file.

A single file must hold a (T, Z, Y, X) series: axes ``TZYX`` (or ``ZTYX``) as
tifffile and ImageJ hyperstacks record them, or an unlabelled 4D series taken
as (T, Z, Y, X). Length-1 axes (an ImageJ channel axis with C == 1) are
dropped; more channels or colour samples are refused. Data are read through
tifffile's zarr view, so one step (a few pages) is in memory at once.

Spacing (dx, dy, dz), x first, comes from the ``spacing`` argument when given, else from
the first file: x and y from the XResolution/YResolution tags, z from the
ImageJ ``spacing`` entry, 1.0 where missing.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from chronocl.core.errors import ChronoclError, InvalidDataError
from chronocl.core.paths import check_output
from chronocl.data.formats.contract import Reader, has_suffix, time_attrs
from chronocl.data.inputs import expand_inputs
from chronocl.data.metadata import SUPPORTED_DTYPES, parse_spacing
from chronocl.data.series import write_steps
from chronocl.data.steps import Steps
from chronocl.data.timeseries import TimeSeries

# Words in tifffile's log warnings that mean the file structure is damaged; tifffile logs
# them and carries on with fewer pages (or a wrong series) instead of raising.
_DAMAGE_WORDS = ("invalid", "corrupt", "truncat", "unpack requires", "out of range")


@dataclass
class _Stack:
    path: Path
    shape: tuple[int, ...]  # series shape with length-1 axes dropped
    axes: str
    dtype: np.dtype
    spacing: tuple[float, float, float]  # (dx, dy, dz), x first
    kept: tuple[int, ...]  # index in the file's series of each axis in `shape`


def ingest_tiff(
    inputs: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    *,
    spacing: Sequence[float] | None = None,
    times: Sequence | None = None,
    time_unit: str | None = None,
    nan_fill: float | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> TimeSeries:
    """Several 3D TIFF stacks (one per step, globs allowed) or one 4D TIFF -> store at `out`;
    `spacing` is (dx, dy, dz), x first (default: the first file's)."""
    files = expand_inputs(inputs)
    check_output(out, overwrite)
    steps = tiff_steps(files, spacing=spacing, times=times, time_unit=time_unit)
    return write_steps(out, steps, overwrite=overwrite, progress=progress, nan_fill=nan_fill)


def tiff_steps(
    inputs: Sequence[str | os.PathLike],
    *,
    spacing: Sequence[float] | None = None,
    times: Sequence | None = None,
    time_unit: str | None = None,
) -> Steps:
    """The steps of TIFF stacks, checked: `ingest_tiff` before it writes."""
    files = expand_inputs(inputs)
    stacks = [_inspect(f) for f in files]
    if len(stacks) == 1:
        st = stacks[0]
        t_axis = _time_axis(st)
        n_steps = st.shape[t_axis]
        volume = tuple(n for i, n in enumerate(st.shape) if i != t_axis)
        if len(volume) == 2:
            volume = (1, *volume)
        labels = [f"{st.path.name} step {t}" for t in range(n_steps)]
        source = f"tiff: {st.path}"

        def steps() -> Iterator[np.ndarray]:
            with _zarr_view(st.path) as arr:
                for t in range(n_steps):
                    at = st.kept[t_axis]
                    index = tuple(t if i == at else slice(None) for i in range(arr.ndim))
                    yield _read(st.path, arr, index).reshape(volume)

    else:
        volume = _volume(stacks[0])
        for st in stacks[1:]:
            if st.dtype != stacks[0].dtype:
                raise InvalidDataError(
                    f"{stacks[0].path.name} holds {stacks[0].dtype.name} but {st.path.name} "
                    f"holds {st.dtype.name}; every time step must have the same data type"
                )
            if _volume(st) != volume:
                raise InvalidDataError(
                    f"{stacks[0].path.name} holds {volume} but {st.path.name} holds "
                    f"{_volume(st)} (Z, Y, X); every time step must have the same shape"
                )
        n_steps = len(stacks)
        labels = [f"{st.path.name} (step {t})" for t, st in enumerate(stacks)]
        source = f"tiff: {files[0].parent}/{files[0].name} .. {files[-1].name} ({len(files)} files)"

        def steps() -> Iterator[np.ndarray]:
            for st in stacks:
                with _zarr_view(st.path) as arr:
                    yield _read(st.path, arr, ()).reshape(volume)

    dtype = stacks[0].dtype
    if dtype.name not in SUPPORTED_DTYPES:
        # write_series takes few dtypes; float32 holds int8/int32/float16/bool exactly
        # (int32/uint32 beyond 2**24 is rounded).
        dtype = np.dtype(np.float32)
    return Steps(
        lambda: (s.astype(dtype, copy=False) for s in steps()),
        n_steps=n_steps,
        volume_shape=volume,
        dtype=dtype,
        spacing=parse_spacing(spacing) if spacing is not None else stacks[0].spacing,
        times=times,
        attrs=time_attrs(time_unit),
        source=source,
        labels=labels,
    )


def _time_axis(st: _Stack) -> int:
    """Index of the time axis of a single file's series; raises unless it is 4D (T, Z, Y, X)."""
    lead = st.axes[:-2]
    if "T" in lead and len(lead) <= 2:
        return lead.index("T")
    if len(lead) == 2:
        return 1 if lead[0] == "Z" else 0
    if len(lead) <= 1:
        raise InvalidDataError(
            f"{st.path.name} holds one {len(st.shape)}D stack ({', '.join(_names(st))}); "
            "give one file per time step or a 4D (T, Z, Y, X) TIFF"
        )
    raise InvalidDataError(
        f"{st.path.name} has {len(st.shape)} axes {st.axes} {st.shape}; "
        "a single TIFF must be 4D (T, Z, Y, X)"
    )


def _names(st: _Stack) -> list[str]:
    return ["Z", "Y", "X"] if len(st.shape) == 3 else ["Y", "X"]


def _volume(st: _Stack) -> tuple[int, int, int]:
    """(Z, Y, X) of a file that is one time step (a 2D image counts as Z = 1)."""
    if len(st.shape) == 2:
        return (1, *st.shape)
    if len(st.shape) == 3:
        return st.shape  # type: ignore[return-value]
    raise InvalidDataError(
        f"{st.path.name} has {len(st.shape)} axes {st.axes} {st.shape}; with several files "
        "each must be one 3D (Z, Y, X) stack (or give a 4D file on its own)"
    )


@contextlib.contextmanager
def _damage_log() -> Iterator[list[str]]:
    """Collect tifffile's log warnings about damaged structure while the block runs."""
    found: list[str] = []

    class _Catch(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            msg = record.getMessage()
            if any(w in msg.lower() for w in _DAMAGE_WORDS):
                found.append(msg)

    log = logging.getLogger("tifffile")
    handler = _Catch(logging.WARNING)
    log.addHandler(handler)
    try:
        yield found
    finally:
        log.removeHandler(handler)


def _unreadable(p: Path, reason: object) -> InvalidDataError:
    text = " ".join(str(reason).split()) or type(reason).__name__
    if len(text) > 120:
        text = text[:117] + "..."
    return InvalidDataError(f"cannot read {p.name} as TIFF ({text})")


def _inspect(p: Path) -> _Stack:
    import tifffile

    try:
        with _damage_log() as damage, tifffile.TiffFile(p) as tif:
            series = tif.series[0]
            shape, axes = tuple(series.shape), str(series.axes)
            dtype = np.dtype(series.dtype)
            nbytes, offset = int(series.nbytes), series.dataoffset
            page = tif.pages.first
            ij = tif.imagej_metadata or {}
            spacing = (
                _resolution(page.tags.get("XResolution")),
                _resolution(page.tags.get("YResolution")),
                _positive(ij.get("spacing")),
            )
    except ChronoclError:
        raise
    except Exception as exc:  # tifffile raises many kinds on damaged or non-TIFF files
        raise _unreadable(p, exc) from None
    if damage:
        raise _unreadable(p, f"truncated or corrupt: {damage[0]}")
    if offset is not None and offset + nbytes > p.stat().st_size:
        raise _unreadable(p, "truncated: the image data run past the end of the file")
    keep = [i for i, n in enumerate(shape) if n != 1 and axes[i] not in "YX"]
    keep += [i for i, a in enumerate(axes) if a in "YX"]
    keep.sort()
    shape, axes = tuple(shape[i] for i in keep), "".join(axes[i] for i in keep)
    if not axes.endswith("YX"):
        raise InvalidDataError(f"{p.name} has axes {axes} {shape}; expected images (Y, X) last")
    extra = [a for a in axes if a in "CS"]
    if extra:
        raise InvalidDataError(
            f"{p.name} has {shape[axes.index(extra[0])]} channels/samples (axes {axes} {shape}); "
            "only single-channel stacks are supported (tifffile writes a 3- or 4-slice stack as "
            "RGB unless photometric='minisblack')"
        )
    return _Stack(p, shape, axes, dtype.newbyteorder("="), spacing, tuple(keep))


@contextlib.contextmanager
def _zarr_view(p: Path):
    """The first series of `p` as a lazy zarr array (reads only the pages that are indexed)."""
    import tifffile
    import zarr

    try:
        tif = tifffile.TiffFile(p)
    except Exception as exc:  # the file changed since it was inspected
        raise _unreadable(p, exc) from None
    try:
        with tif.series[0].aszarr() as store:
            arr = zarr.open_array(store=store, mode="r")
            yield arr
    finally:
        tif.close()


def _read(p: Path, arr, index: tuple) -> np.ndarray:
    try:
        with _damage_log() as damage:
            data = np.asarray(arr[index])
    except ChronoclError:
        raise
    except Exception as exc:  # decompression or short-read errors on a damaged file
        raise _unreadable(p, exc) from None
    if damage:
        raise _unreadable(p, f"truncated or corrupt: {damage[0]}")
    return data


def _resolution(tag) -> float:
    """Pixel size from an X/YResolution tag (pixels per unit), 1.0 when missing or unusable."""
    if tag is None:
        return 1.0
    try:
        num, den = tag.value
        size = Fraction(int(den), int(num))
    except (TypeError, ValueError, ZeroDivisionError):
        return 1.0
    return float(size) if size > 0 else 1.0


def _positive(value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return 1.0
    return v if np.isfinite(v) and v > 0 else 1.0


READER = Reader(
    "tiff",
    ingest_tiff,
    options={"spacing": None, "times": None, "time_unit": None},
    recognises=has_suffix(".tif", ".tiff"),  # .ome.tif(f) too
    steps=tiff_steps,
)
