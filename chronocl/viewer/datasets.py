"""The data sets a viewer serves: each series named for the client, with its statistics, the
histogram of the values in a window (or of the changes between its consecutive steps, for a
change mode), and v(t) at a voxel or over a box for the probe.

A window's histogram never reads full-resolution steps: it is the sum of small per-step
counts, each counted once per (step, range) from a small sample of that step (`step_sample`):
the series' coarsest stored level that still holds about `TUNING.hist_min_voxels` voxels (the
"mean" pool), else a strided sample of the step that decodes at most `TUNING.hist_read_bytes` of
its stored chunks (a series in memory: a strided view of its array).
"""

from __future__ import annotations

import math
import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.core.time_labels import display_labels, has_labels
from chronocl.core.tuning import TUNING
from chronocl.core.values import normalize
from chronocl.data.level_sources import AdoptedLevels
from chronocl.data.probe import TimeCurve, probe
from chronocl.data.pyramid import level_shapes
from chronocl.data.remote import storage_options_for
from chronocl.data.remote_store import is_url
from chronocl.data.series import TimeSeries, open_series


def sample_steps(steps: Sequence[int], stride: int = 1) -> list[int]:
    """The steps of a window whose values make its histogram: all when there are at most
    TUNING.hist_sample_steps, else every m-th on the grid of the window's stride, so that a window
    sliding by one stride keeps most of its samples (and their cache)."""
    steps = sorted(int(s) for s in steps)
    if len(steps) <= TUNING.hist_sample_steps:
        return steps
    m = -(-len(steps) // TUNING.hist_sample_steps)
    return [s for s in steps if (s // max(1, stride)) % m == 0]


def sample_level(series: TimeSeries) -> int:
    """The level a step's histogram sample is read from: the coarsest level read from storage
    (not pooled on the fly from level 0) with at least TUNING.hist_min_voxels voxels; 0: none."""
    source = series.level_source
    if source is None and series.path is not None:
        stored = range(1, series.n_levels)  # the store's own levels
    elif isinstance(source, AdoptedLevels):
        stored = sorted(n for n in source.arrays if n > 0)  # a format's own "mean" levels
    else:
        return 0  # levels would be pooled from level 0: sample level 0 instead
    shapes = level_shapes(series.volume_shape)
    big = [
        n for n in stored if n <= len(shapes) and math.prod(shapes[n - 1]) >= TUNING.hist_min_voxels
    ]
    return max(big, default=0)


def _stride(voxels: int) -> int:
    """The stride along every axis that leaves about TUNING.hist_sample_voxels of `voxels`."""
    return max(1, round(float(np.cbrt(voxels / TUNING.hist_sample_voxels))))


def raw_sample(series: TimeSeries, step: int, level: int | None = None) -> np.ndarray:
    """The raw values of one step that its histogram counts (see the module's docstring), read
    from `level` (None: `sample_level`'s)."""
    level = sample_level(series) if level is None else level
    source = series.level(level) if level else series
    shape = source.volume_shape
    s = _stride(math.prod(shape))
    every = slice(None, None, s)
    if level or source.path is None:  # a small level, or a series in memory
        if source.host is not None:
            return np.array(source.host[step, every, every, every])
        return source.read_region(slice(step, step + 1), every, every, every)[0]
    # A stored step without levels: whole z chunks, decoding at most TUNING.hist_read_bytes of them.
    zc = source.z_chunk
    n_chunks = -(-shape[0] // zc)
    chunk_bytes = zc * shape[1] * shape[2] * source.dtype.itemsize
    keep = max(1, min(n_chunks, TUNING.hist_read_bytes // max(1, chunk_bytes)))
    if keep == n_chunks:
        return source.read_region(slice(step, step + 1), every, every, every)[0]
    s = _stride(keep * zc * shape[1] * shape[2])
    every = slice(None, None, s)
    # The middle chunk of each of `keep` equal stretches of z (a volume's edges are often empty).
    chunks = sorted({(2 * i + 1) * n_chunks // (2 * keep) for i in range(keep)})
    rows = [slice(c * zc, min(shape[0], (c + 1) * zc), s) for c in chunks]
    return np.concatenate(
        [source.read_region(slice(step, step + 1), z, every, every)[0] for z in rows]
    )


class Dataset:
    """One series the server was started with, named for the client (`path`: its store, which
    saved sessions record); statistics cached."""

    def __init__(self, name: str, series: TimeSeries, path: str | None = None) -> None:
        self.name = name
        self.series = series
        self.path = path
        self._lock = threading.Lock()
        self._samples: OrderedDict[int, np.ndarray] = OrderedDict()
        self._counts: OrderedDict[tuple[int, float, float], np.ndarray] = OrderedDict()
        self._level: int | None = None  # the level step samples are read from

    def info(self, index: int) -> dict:
        s = self.series
        st = s.stats
        t, z, y, x = s.shape
        steps = list(range(t))
        return {
            "index": index,
            "name": self.name,
            "shape": {"t": t, "z": z, "y": y, "x": x},
            "dtype": str(s.dtype),
            "vmin": s.vmin,
            "vmax": s.vmax,
            "step_min": [float(v) for v in st.step_min],
            "step_max": [float(v) for v in st.step_max],
            "step_mean": [float(v) for v in st.step_mean],
            "times": [str(v) for v in s.times],
            # What the timeline writes for each step; None: the store has no time labels.
            "time_labels": (
                display_labels(steps, s.times, unit=s.time_unit)
                if has_labels(steps, s.times, s.time_unit)
                else None
            ),
            # The times' unit ('s', 'h'; None: none given), for the timeline's tick labels.
            "time_unit": s.time_unit,
        }

    def step_sample(self, step: int) -> np.ndarray:
        """Normalised values u of one step's histogram sample, about
        `TUNING.hist_sample_voxels` of them (`raw_sample`; cached)."""

        def read() -> np.ndarray:
            s = self.series
            if self._level is None:
                self._level = sample_level(s)  # (reads the store's level metadata)
            return normalize(raw_sample(s, step, self._level), s.vmin, s.vmax).ravel()

        return self._cached(self._samples, step, TUNING.hist_cache_steps, read)

    def _cached(
        self, cache: OrderedDict, key: object, cap: int, compute: Callable[[], np.ndarray]
    ) -> np.ndarray:
        """`cache[key]`, else `compute()` stored there, keeping the `cap` most recently used;
        computed outside the lock, so that a slow read holds up no other lookup."""
        with self._lock:
            got = cache.get(key)
            if got is not None:
                cache.move_to_end(key)
                return got
        got = compute()
        with self._lock:
            cache[key] = got
            while len(cache) > cap:
                cache.popitem(last=False)
        return got

    def step_counts(self, step: int, lo: float, hi: float) -> np.ndarray:
        """`TUNING.hist_bins` counts of one step's sample over [lo, hi] (cached per step and
        range)."""
        key = (int(step), float(lo), float(hi))

        def count() -> np.ndarray:
            sample = self.step_sample(step)
            return np.histogram(sample, bins=TUNING.hist_bins, range=(lo, hi))[0].astype(np.int64)

        return self._cached(self._counts, key, TUNING.hist_cache_counts, count)

    def change_counts(
        self, before: int, step: int, lo: float, hi: float, value_range: tuple[float, float]
    ) -> np.ndarray:
        """`TUNING.hist_bins` counts over [lo, hi] of the changes δ from step `before` to `step` in
        their samples (the same voxels), as the change mode compares them: each value clipped
        to `value_range` and scaled to it, δ = |w(step) - w(before)| (cached per pair and
        ranges)."""
        key = (int(before), int(step), float(lo), float(hi), *map(float, value_range))
        s, (vlo, vhi) = self.series, value_range
        span = max(float(vhi) - float(vlo), 1e-30)

        def w(t: int) -> np.ndarray:  # the sample's u (series range) as the TF's range sees it
            v = float(s.vmin) + self.step_sample(t).astype(np.float64) * (s.vmax - s.vmin)
            return np.clip((v - vlo) / span, 0.0, 1.0)

        def count() -> np.ndarray:
            delta = np.abs(w(step) - w(before))
            return np.histogram(delta, bins=TUNING.hist_bins, range=(lo, hi))[0].astype(np.int64)

        return self._cached(self._counts, key, TUNING.hist_cache_counts, count)

    def histogram(
        self,
        lo: float = 0.0,
        hi: float = 1.0,
        steps: Sequence[int] | None = None,
        stride: int = 1,
        given_up: Callable[[], bool] | None = None,
        of: str = "value",
        value_range: Sequence[float] | None = None,
    ) -> dict | None:
        """Counts in `TUNING.hist_bins` bins over [lo, hi] in the window of `steps` (None: the whole
        series) of u, or (`of` "change") of the changes δ between its consecutive steps scaled
        to `value_range` (None: the series'), which a change mode's data TF maps: the sum of
        the per-step counts (`step_counts`, `change_counts`) of the steps `sample_steps`
        picks (each with the step before it in the window, for changes), which are in
        "steps". None where `given_up()` turned true between two steps (a newer request
        replaces this one; the steps counted stay cached)."""
        if not hi > lo:
            raise InvalidParameterError(f"histogram range [{lo}, {hi}] must have lo < hi")
        window = sorted(int(t) for t in (range(self.series.n_steps) if steps is None else steps))
        chosen = sample_steps(window, stride)
        vr = (self.series.vmin, self.series.vmax) if value_range is None else value_range
        before = dict(zip(window[1:], window[:-1], strict=True))
        if of == "change":
            chosen = [t for t in chosen if t in before]  # the first step changes from nothing
        counts = np.zeros(TUNING.hist_bins, np.int64)
        for step in chosen:
            if given_up is not None and given_up():
                return None
            if of == "change":
                counts += self.change_counts(before[step], step, lo, hi, tuple(vr))
            else:
                counts += self.step_counts(step, lo, hi)
        return {"range": [lo, hi], "counts": counts.tolist(), "steps": chosen, "of": of}

    def curve(self, voxel: tuple[int, int, int] | None = None, box: object = None) -> TimeCurve:
        """v(t) at `voxel` (x, y, z), or the mean/min/max over `box` ((x0, x1), (y0, y1),
        (z0, z1)), over every step of the series: `chronocl.data.probe.probe`'s curve."""
        if box is not None:
            return probe(self.series, region=box)
        return probe(self.series, *voxel)  # type: ignore[misc]


def find_dataset(datasets: list[Dataset], ref: int | str, path: str | None = None) -> int:
    """The index of a data set named by index or name (or, failing the name, by its store's
    path); UnknownNameError listing those there are."""
    if isinstance(ref, int):
        if ref < len(datasets):
            return ref
    else:
        for i, d in enumerate(datasets):
            if d.name == ref:
                return i
        for i, d in enumerate(datasets):
            if path is not None and d.path == path:
                return i
    names = ", ".join(f"{i}: {d.name}" for i, d in enumerate(datasets))
    raise UnknownNameError(f"unknown data set {ref!r}; choose one of {names}")


def open_datasets(
    stores: Sequence[str | os.PathLike], options: dict | None = None
) -> list[Dataset]:
    """Open each store (a path, or an http(s):// or s3:// URL read in place with
    storage `options`); names are the stores' stems, made unique with a suffix."""
    if not stores:
        raise InvalidParameterError("no store given; name at least one series store to view")
    datasets: list[Dataset] = []
    seen: set[str] = set()
    for store in stores:
        if is_url(store):
            where = str(store)
            series = open_series(where, storage_options=storage_options_for(where, options or {}))
            base = where.rstrip("/").rsplit("/", 1)[-1]
        else:
            series = open_series(store)
            where, base = str(Path(store).resolve()), Path(store).name
        base = base.removesuffix(".zarr") or "series"
        name, n = base, 2
        while name in seen:
            name, n = f"{base}-{n}", n + 1
        seen.add(name)
        datasets.append(Dataset(name, series, where))
    return datasets
