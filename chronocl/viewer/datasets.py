"""The data sets a viewer serves: each series named for the client, with its statistics, the
histogram of the values in a window (from cached per-step samples), and v(t) at a voxel or over
a box for the probe."""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.core.time_labels import display_labels, has_labels
from chronocl.data.probe import TimeCurve, probe
from chronocl.data.series import TimeSeries, open_series

HIST_BINS = 128
HIST_SAMPLE_STEPS = 8  # at most this many steps of the window are sampled
HIST_SAMPLE_VOXELS = 2**18  # about this many voxels of each (strided along every axis)
HIST_CACHE_STEPS = 64  # steps whose samples are kept (a window sliding by one reads one step)


def sample_steps(steps: Sequence[int], stride: int = 1) -> list[int]:
    """The steps of a window whose values make its histogram: all when there are at most
    HIST_SAMPLE_STEPS, else every m-th on the grid of the window's stride, so that a window
    sliding by one stride keeps most of its samples (and their cache)."""
    steps = sorted(int(s) for s in steps)
    if len(steps) <= HIST_SAMPLE_STEPS:
        return steps
    m = -(-len(steps) // HIST_SAMPLE_STEPS)
    return [s for s in steps if (s // max(1, stride)) % m == 0]


class Dataset:
    """One series the server was started with, named for the client (`path`: its store, which
    saved sessions record); statistics cached."""

    def __init__(self, name: str, series: TimeSeries, path: str | None = None) -> None:
        self.name = name
        self.series = series
        self.path = path
        self._lock = threading.Lock()
        self._samples: OrderedDict[int, np.ndarray] = OrderedDict()

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
        }

    def step_sample(self, step: int) -> np.ndarray:
        """Normalised values u of one step, strided to about HIST_SAMPLE_VOXELS (cached)."""
        with self._lock:
            got = self._samples.get(step)
            if got is not None:
                self._samples.move_to_end(step)
                return got
        s = self.series
        shape = np.array(s.volume_shape)
        stride = max(1, round(float(np.cbrt(shape.prod() / HIST_SAMPLE_VOXELS))))
        u = s.normalized([step], 0, int(shape[0]))[0]
        got = np.ascontiguousarray(u[::stride, ::stride, ::stride], np.float32).ravel()
        with self._lock:
            self._samples[step] = got
            while len(self._samples) > HIST_CACHE_STEPS:
                self._samples.popitem(last=False)
        return got

    def histogram(
        self, lo: float = 0.0, hi: float = 1.0, steps: Sequence[int] | None = None, stride: int = 1
    ) -> dict:
        """Counts of u in HIST_BINS bins over [lo, hi] in the window of `steps` (None: the
        whole series), sampled by `sample_steps`; which steps were sampled is in "steps"."""
        if not hi > lo:
            raise InvalidParameterError(f"histogram range [{lo}, {hi}] must have lo < hi")
        chosen = sample_steps(range(self.series.n_steps) if steps is None else steps, stride)
        counts = np.zeros(HIST_BINS, np.int64)
        for step in chosen:
            counts += np.histogram(self.step_sample(step), bins=HIST_BINS, range=(lo, hi))[0]
        return {"range": [lo, hi], "counts": counts.tolist(), "steps": chosen}

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


def open_datasets(stores: Sequence[str | os.PathLike]) -> list[Dataset]:
    """Open each store; names are the stores' stems, made unique with a suffix."""
    if not stores:
        raise InvalidParameterError("no store given; name at least one series store to view")
    datasets: list[Dataset] = []
    seen: set[str] = set()
    for store in stores:
        series = open_series(store)
        base = Path(store).name.removesuffix(".zarr") or "series"
        name, n = base, 2
        while name in seen:
            name, n = f"{base}-{n}", n + 1
        seen.add(name)
        datasets.append(Dataset(name, series, str(Path(store).resolve())))
    return datasets
