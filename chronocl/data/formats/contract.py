"""What a format offers, one small contract per capability, for the registry to list.

A format module declares the capabilities it has as module constants: ``READER`` (ingest its
files into a chronocl store), ``OUTPUT`` (save a chronovolume under a path suffix) and
``EXPORTER`` (write series steps for another tool). `chronocl.data.formats.registry` lists
them; the fronts (`ingest`, `outputs`, `export`) choose by the registry.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from chronocl.core.times_meta import check_time_unit
from chronocl.data.steps import Steps

if TYPE_CHECKING:
    from chronocl.data.timeseries import TimeSeries

# Options the ingest front offers every reader (each reader's `common` says which it takes).
COMMON_OPTIONS = ("nan_fill", "overwrite", "progress")


@dataclass(frozen=True)
class Reader:
    """An ingest reader: `read(inputs, out, **options)` writes a new store at `out`.

    `inputs` is the list of input paths, or the one input itself when `single`. `options`
    are the reader's own options, each with the value that means "not given"; `common`, the
    COMMON_OPTIONS it takes. `recognises(path)` tells its inputs by the first one; None marks
    the reader for the files that no other reader recognises.
    """

    name: str
    read: Callable[..., TimeSeries]
    options: Mapping[str, object]
    recognises: Callable[[Path], bool] | None
    single: bool = False
    common: tuple[str, ...] = COMMON_OPTIONS
    # `steps(inputs, **options)`: the same inputs as `Steps`, unwritten (for --magnitude).
    steps: Callable[..., Steps] | None = None


def time_attrs(time_unit: str | None) -> dict[str, str]:
    """The store attributes that record the unit of the steps' times (none when not given)."""
    return {"time_unit": check_time_unit(time_unit)} if time_unit else {}


def has_suffix(*suffixes: str) -> Callable[[Path], bool]:
    """A `Reader.recognises` for files (not folders) whose name ends in one of `suffixes`."""
    return lambda path: path.suffix.lower() in suffixes and not path.is_dir()


@dataclass(frozen=True)
class Output:
    """A chronovolume format chosen by path suffix: `save(cv, path, overwrite=False)`."""

    suffix: str
    opens_in: str  # the program that opens it, named in errors
    save: Callable[..., Path]


@dataclass(frozen=True)
class StepExport:
    """One export of series steps, as the export front hands it to a format's exporter.

    `read(step)` gives the step's rows [z0, z1) as (z1 - z0, Y, X); `target` is the checked
    output path (a file or a folder, as the format writes).
    """

    series: TimeSeries
    target: Path
    steps: Sequence[int]
    z0: int
    z1: int
    read: Callable[[int], np.ndarray]
    overwrite: bool = False
    progress: bool = False

    @property
    def stem(self) -> str:
        """The target's name without suffix: what the per-step files are named after."""
        return self.target.stem or self.target.name

    def step_name(self, step: int, suffix: str) -> str:
        """The file name of one step: ``<stem>_t{step:05d}<suffix>``."""
        return f"{self.stem}_t{step:05d}{suffix}"


@dataclass(frozen=True)
class Exporter:
    """A step export format: `export(job)` writes `job` and returns the paths written."""

    name: str
    export: Callable[[StepExport], list[Path]]
