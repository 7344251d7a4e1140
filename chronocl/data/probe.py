"""Probes outside the viewer: v(t) at one voxel, or the mean, min and max over a box, per step.

`probe(series, x, y, z)` and `probe(series, region=...)` read only the voxel's or the box's
sub-block of each step (`TimeSeries.read_region`: zarr decodes the chunks that block touches,
never a whole step where the chunking splits it, and through the store's damage checks, so a
damaged chunk is `StoreCorruptError`, never zeros), a run of steps per read, with a progress
bar once the work takes more than a second. They return a `TimeCurve`: the values per step
with the steps and the series' time labels. `TimeCurve.to_csv` writes ``step,time,value`` (a
box: ``step,time,mean,min,max``); `TimeCurve.plot` draws it with matplotlib (no display)
against the time labels, an integration window shaded. Both write atomically.

Coordinates are voxel indices x, y, z: x indexes the fastest axis of the store's (T, Z, Y, X).
A box is three half-open ranges ``x0:x1,y0:y1,z0:z1`` as Python slices, an omitted bound
meaning the volume's edge (``:,:,10:12`` is two whole z planes).
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from chronocl.core.atomic import atomic_file
from chronocl.core.errors import InvalidParameterError
from chronocl.core.progress import meter
from chronocl.core.selection import parse_selection
from chronocl.core.tuning import TUNING
from chronocl.data.probe_plot import figure

if TYPE_CHECKING:
    from chronocl.data.timeseries import TimeSeries

AXES = ("x", "y", "z")
SUFFIXES = (".csv", ".png")

Box = tuple[tuple[int, int], tuple[int, int], tuple[int, int]]  # (x0, x1), (y0, y1), (z0, z1)


@dataclass(frozen=True, eq=False)
class TimeCurve:
    """Values over time at a voxel (`point`) or over a box (`box`), one per step.

    `values` is the voxel's value, or the box's mean, at each of `steps`, whose time labels are
    `times`; a box also has the `min` and `max` over the box per step. Values are float64.
    """

    steps: np.ndarray
    times: tuple
    values: np.ndarray
    min: np.ndarray | None = None
    max: np.ndarray | None = None
    point: tuple[int, int, int] | None = None
    box: Box | None = None
    source: str = ""
    time_unit: str | None = None  # of numeric `times` ('s'), where the store names one

    @property
    def is_box(self) -> bool:
        return self.box is not None

    @property
    def mean(self) -> np.ndarray | None:
        """The mean over the box per step (None for a voxel)."""
        return self.values if self.is_box else None

    def __len__(self) -> int:
        return len(self.steps)

    def describe(self) -> str:
        """'voxel x=3, y=4, z=5' or 'box x 0:4, y 0:4, z 2:3 (32 voxels)'."""
        if self.box is None:
            x, y, z = self.point  # type: ignore[misc]
            return f"voxel x={x}, y={y}, z={z}"
        ranges = ", ".join(f"{a} {lo}:{hi}" for a, (lo, hi) in zip(AXES, self.box, strict=True))
        n = math.prod(hi - lo for lo, hi in self.box)
        return f"box {ranges} ({n} voxel{'s' if n != 1 else ''})"

    def window_steps(self, window: object) -> tuple[int, ...]:
        """The steps of `window` (a Selection, 't0:t1[:stride]', a list; None: none)."""
        if window is None:
            return ()
        return parse_selection(window, len(self.steps)).steps

    def csv_text(self, window: object = None) -> str:
        """The CSV: step,time,value (a box: step,time,mean,min,max), one row per step; with a
        `window`, a last column in_window (1 for the window's steps, else 0)."""
        chosen = set(self.window_steps(window))
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        header = ["step", "time", *(["mean", "min", "max"] if self.is_box else ["value"])]
        writer.writerow(header + (["in_window"] if window is not None else []))
        for i, step in enumerate(self.steps):
            row = [int(step), self.times[i], repr(float(self.values[i]))]
            if self.is_box:
                row += [repr(float(self.min[i])), repr(float(self.max[i]))]  # type: ignore[index]
            if window is not None:
                row.append(int(int(step) in chosen))
            writer.writerow(row)
        return buf.getvalue()

    def to_csv(
        self, path: str | os.PathLike, window: object = None, overwrite: bool = False
    ) -> Path:
        """Write `csv_text` to `path` atomically; returns the path."""
        check_suffix(path, (".csv",))
        text = self.csv_text(window)
        with atomic_file(path, overwrite) as tmp:
            tmp.write_text(text, encoding="utf-8")
        return Path(path)

    def figure(self, window: object = None, title: str | None = None, time_labels="labels"):
        """A matplotlib Figure of the curve against the time labels (see `plot`)."""
        return figure(self, window, title, time_labels)

    def plot(
        self,
        path: str | os.PathLike,
        window: object = None,
        title: str | None = None,
        overwrite: bool = False,
        time_labels: str = "labels",
    ) -> Path:
        """Draw the curve to a PNG at `path`, atomically; returns the path (see `plot_curve`);
        `time_labels="steps"` plots against the step numbers instead of the time labels."""
        return plot_curve(self, path, window, title, overwrite, time_labels)


# -- what is probed ----------------------------------------------------------------------------
def parse_point(text: str, what: str = "point") -> tuple[int, int, int]:
    """'x,y,z' as three whole voxel indices."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        point = tuple(int(p) for p in parts)
    except ValueError:
        point = ()
    if len(point) != 3:
        raise InvalidParameterError(
            f"{what} {text!r} must be three whole voxel indices x,y,z, e.g. 10,20,5"
        )
    return point  # type: ignore[return-value]


def parse_box(text: str, what: str = "box") -> tuple[tuple[int | None, int | None], ...]:
    """'x0:x1,y0:y1,z0:z1' as three (lo, hi) pairs, None where a bound is omitted."""
    bad = InvalidParameterError(
        f"{what} {text!r} must be three ranges x0:x1,y0:y1,z0:z1 of whole voxel indices "
        "(end excluded; an omitted bound is the volume's edge), e.g. 10:20,0:16,5:6"
    )
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 3:
        raise bad
    ranges = []
    for part in parts:
        bounds = part.split(":")
        if len(bounds) != 2:
            raise bad
        try:
            ranges.append(tuple(int(b) if b.strip() else None for b in bounds))
        except ValueError:
            raise bad from None
    return tuple(ranges)  # type: ignore[return-value]


def check_point(
    point: Sequence[object], volume_shape: Sequence[int], what: str = "probe point"
) -> tuple[int, int, int]:
    """Whole voxel indices (x, y, z) inside a volume of `volume_shape` (Z, Y, X)."""
    nz, ny, nx = volume_shape
    sizes = (nx, ny, nz)
    out = []
    for axis, v, n in zip(AXES, point, sizes, strict=True):
        if v is None:
            raise InvalidParameterError(
                f"{what} lacks {axis}; give all of x, y, z (voxel indices) or a region"
            )
        i = _whole(v, f"{what} {axis}={v!r}")
        if not 0 <= i < n:
            raise InvalidParameterError(
                f"{what} {axis}={i} is outside the volume's {n} voxels along {axis} "
                f"(x, y, z sizes {nx}, {ny}, {nz}); choose 0 <= {axis} <= {n - 1}"
            )
        out.append(i)
    return tuple(out)  # type: ignore[return-value]


def check_box(region: object, volume_shape: Sequence[int], what: str = "region") -> Box:
    """A box as (lo, hi) per axis x, y, z inside a volume of `volume_shape` (Z, Y, X).

    `region` is 'x0:x1,y0:y1,z0:z1' or three items, each a slice, a (lo, hi) pair (either may
    be None: the edge) or one index (that plane alone).
    """
    nz, ny, nx = volume_shape
    sizes = (nx, ny, nz)
    if isinstance(region, str):
        region = parse_box(region, what)
    if not isinstance(region, Sequence) or len(region) != 3:
        raise InvalidParameterError(
            f"{what} {region!r} must give x, y and z ranges, e.g. 'x0:x1,y0:y1,z0:z1' or "
            "(slice(10, 20), slice(0, 16), 5)"
        )
    box = []
    for axis, item, n in zip(AXES, region, sizes, strict=True):
        lo, hi = _bounds(axis, item, what)
        lo = 0 if lo is None else lo
        hi = n if hi is None else hi
        if not 0 <= lo < hi <= n:
            raise InvalidParameterError(
                f"{what} {axis} range {lo}:{hi} does not fit the volume's {n} voxels along "
                f"{axis} (x, y, z sizes {nx}, {ny}, {nz}); use 0 <= {axis}0 < {axis}1 <= {n}"
            )
        box.append((lo, hi))
    return tuple(box)  # type: ignore[return-value]


def _bounds(axis: str, item: object, what: str) -> tuple[int | None, int | None]:
    if isinstance(item, slice):
        if item.step not in (None, 1):
            raise InvalidParameterError(
                f"{what} {axis} slice {item} has a step; a box takes every voxel, drop the step"
            )
        lo, hi = item.start, item.stop
    elif isinstance(item, Sequence) and not isinstance(item, str) and len(item) == 2:
        lo, hi = item
    elif isinstance(item, int | np.integer) and not isinstance(item, bool):
        lo, hi = int(item), int(item) + 1
    else:
        raise InvalidParameterError(
            f"{what} {axis} range {item!r} must be a slice, a (lo, hi) pair or one index"
        )
    return (
        None if lo is None else _whole(lo, f"{what} {axis} bound {lo!r}"),
        None if hi is None else _whole(hi, f"{what} {axis} bound {hi!r}"),
    )


def _whole(v: object, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int | np.integer):
        raise InvalidParameterError(f"{what} is not a voxel index; give a whole number")
    return int(v)


# -- probing -----------------------------------------------------------------------------------
def probe(
    series: TimeSeries,
    x: int | None = None,
    y: int | None = None,
    z: int | None = None,
    *,
    region: object = None,
    progress: bool = False,
) -> TimeCurve:
    """v(t) at voxel (x, y, z), or the mean, min and max over the box `region`, at every step.

    Every argument is checked before anything is read. Each read covers a run of steps of the
    voxel's or the box's sub-block only; `progress` shows a bar once it takes over a second.
    """
    point, box = None, None
    if region is None:
        point = check_point((x, y, z), series.volume_shape)
        (x0, x1), (y0, y1), (z0, z1) = ((v, v + 1) for v in point)
    else:
        if (x, y, z) != (None, None, None):
            raise InvalidParameterError(
                "give a point (x, y, z) or a region, not both; "
                "probe(x, y, z) or probe(region='x0:x1,y0:y1,z0:z1')"
            )
        box = check_box(region, series.volume_shape)
        (x0, x1), (y0, y1), (z0, z1) = box
    n_steps = series.n_steps
    block = (z1 - z0) * (y1 - y0) * (x1 - x0)
    nbytes = block * series.dtype.itemsize
    per_read = max(1, min(TUNING.probe_steps_per_read, TUNING.probe_read_bytes // max(1, nbytes)))
    values = np.empty(n_steps, np.float64)
    lows = np.empty(n_steps, np.float64) if box else None
    highs = np.empty(n_steps, np.float64) if box else None
    where = (slice(z0, z1), slice(y0, y1), slice(x0, x1))
    with _steps_meter(n_steps, progress) as advance:
        for t0 in range(0, n_steps, per_read):
            t1 = min(n_steps, t0 + per_read)
            flat = series.read_region(slice(t0, t1), *where).reshape(t1 - t0, block)
            if box is None:
                values[t0:t1] = flat[:, 0]
            else:
                values[t0:t1] = flat.mean(axis=1, dtype=np.float64)
                lows[t0:t1] = flat.min(axis=1)  # type: ignore[index]
                highs[t0:t1] = flat.max(axis=1)  # type: ignore[index]
            advance(t1 - t0, (t1 - t0) * nbytes)
    return TimeCurve(
        steps=np.arange(n_steps),
        times=tuple(series.times),
        values=values,
        min=lows,
        max=highs,
        point=point,
        box=box,
        source=str(series.path) if series.path is not None else series.source,
        time_unit=series.time_unit,
    )


@contextlib.contextmanager
def _steps_meter(total: int, enabled: bool) -> Iterator[Callable[[int, int], None]]:
    """Yield advance(steps, nbytes); a bar is shown once the work has taken
    `TUNING.probe_bar_after_s`."""
    start = time.perf_counter()
    done = 0
    tick: Callable[[int], None] | None = None
    with contextlib.ExitStack() as stack:

        def advance(n: int, nbytes: int) -> None:
            nonlocal done, tick
            done += n
            if tick is not None:
                for _ in range(n):
                    tick(nbytes // max(n, 1))
                return
            waited = time.perf_counter() - start
            if enabled and done < total and waited > TUNING.probe_bar_after_s:
                tick = stack.enter_context(meter(total, "probe", True, done=done, unit="steps"))

        yield advance


# -- writing -----------------------------------------------------------------------------------
def check_suffix(path: str | os.PathLike, allowed: Sequence[str] = SUFFIXES) -> str:
    """The suffix of `path` ('.csv' or '.png'), lower case; raise for any other."""
    suffix = Path(path).suffix.lower()
    if suffix not in allowed:
        names = " or ".join(allowed)
        raise InvalidParameterError(
            f"output {os.fspath(path)!r} must end in {names}; e.g. curve{allowed[0]}"
        )
    return suffix


def write_curve(
    curve: TimeCurve,
    path: str | os.PathLike,
    window: object = None,
    title: str | None = None,
    overwrite: bool = False,
    time_labels: str = "labels",
) -> Path:
    """Write `curve` as CSV or PNG, as the suffix of `path` says."""
    if check_suffix(path) == ".csv":
        return curve.to_csv(path, window, overwrite)
    return plot_curve(curve, path, window, title, overwrite, time_labels)


def plot_curve(
    curve: TimeCurve,
    path: str | os.PathLike,
    window: object = None,
    title: str | None = None,
    overwrite: bool = False,
    time_labels: str = "labels",
) -> Path:
    """Draw `curve` to a PNG at `path` atomically (matplotlib's Agg canvas, no display)."""
    check_suffix(path, (".png",))
    fig = figure(curve, window, title, time_labels)
    with atomic_file(path, overwrite) as tmp:
        fig.savefig(tmp, format="png")
    return Path(path)
