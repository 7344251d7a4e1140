"""The data sets a viewer serves: each series named for the client, with its statistics, a
cached sample for histograms, and v(t) at a voxel for the probe."""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.data.series import TimeSeries, open_series

HIST_BINS = 128
HIST_SAMPLE_STEPS = 4


class Dataset:
    """One series the server was started with, named for the client (`path`: its store, which
    saved sessions record); statistics cached."""

    def __init__(self, name: str, series: TimeSeries, path: str | None = None) -> None:
        self.name = name
        self.series = series
        self.path = path
        self._lock = threading.Lock()
        self._sample: np.ndarray | None = None

    def info(self, index: int) -> dict:
        s = self.series
        st = s.stats
        t, z, y, x = s.shape
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
        }

    def sample(self) -> np.ndarray:
        """Normalised values u of a few evenly spaced steps (subsampled), for histograms."""
        with self._lock:
            if self._sample is None:
                s = self.series
                n = min(HIST_SAMPLE_STEPS, s.n_steps)
                steps = sorted({round(v) for v in np.linspace(0, s.n_steps - 1, n)})
                nz = s.volume_shape[0]
                stride = 2 if min(s.volume_shape) >= 64 else 1
                parts = []
                for step in steps:
                    u = s.normalized([step], 0, nz)[0]
                    parts.append(u[::stride, ::stride, ::stride].ravel())
                self._sample = np.concatenate(parts).astype(np.float32)
            return self._sample

    def histogram(self, lo: float = 0.0, hi: float = 1.0) -> dict:
        if not hi > lo:
            raise InvalidParameterError(f"histogram range [{lo}, {hi}] must have lo < hi")
        counts, _ = np.histogram(self.sample(), bins=HIST_BINS, range=(lo, hi))
        return {"range": [lo, hi], "counts": counts.astype(int).tolist()}

    def curve(self, z: int, y: int, x: int) -> list[float]:
        """v(t) at one voxel over every step of the series."""
        values = np.asarray(self.series.data[:, z, y, x].compute(), dtype=np.float64)
        return [float(v) for v in values]


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
