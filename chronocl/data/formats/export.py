"""Export time steps of a series for other tools, in a format chosen from the registry.

- ``vti``: a folder OUT of one .vti per step and a .pvd collection, for ParaView
  (`chronocl.data.formats.vti`);
- ``npy``: one file OUT, a (W, Z, Y, X) array of the selected steps (`.npy`);
- ``raw``: a folder OUT of headerless files and a .json saying how to ingest them back (`.raw`).

Outputs appear only when complete (written to a temporary sibling, then renamed).
A z slab ("z0:z1") exports only those z rows; .vti files then carry the slab's origin.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.core.paths import check_apart, check_output
from chronocl.core.selection import parse_selection
from chronocl.data.formats.contract import StepExport
from chronocl.data.formats.registry import EXPORTERS
from chronocl.data.timeseries import TimeSeries

FORMATS = tuple(EXPORTERS)


def export_series(
    series: TimeSeries,
    out: str | os.PathLike,
    *,
    fmt: str,
    window: object = None,
    z: str | Sequence[int] | None = None,
    overwrite: bool = False,
    progress: bool = False,
) -> list[Path]:
    """Export the steps chosen by `window` (default all) and z rows `z` (default all).

    Returns the paths written: for vti the .pvd first, for raw the .json first, then the
    per-step files in step order; for npy the one file.
    """
    check_apart(out, [series.path])  # never onto, into or around the input
    kind = str(fmt).lower().lstrip(".")
    if kind not in EXPORTERS:
        raise UnknownNameError(f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}")
    steps = parse_selection(window, series.n_steps, series.times).steps
    z0, z1 = parse_slab(z, series.shape[1])
    target = check_output(out, overwrite)
    job = StepExport(
        series,
        target,
        steps,
        z0,
        z1,
        read=lambda step: _read_step(series, step, z0, z1),
        overwrite=overwrite,
        progress=progress,
    )
    return EXPORTERS[kind].export(job)


def parse_slab(z: str | Sequence[int] | None, nz: int) -> tuple[int, int]:
    """Read a z slab 'z0:z1' (either end may be left out), (z0, z1) or None (all) into rows."""
    if z is None:
        return 0, nz
    try:
        if isinstance(z, str):
            parts = [p.strip() for p in z.split(":")]
            if len(parts) != 2:
                raise ValueError(z)
            z0 = int(parts[0]) if parts[0] else 0
            z1 = int(parts[1]) if parts[1] else nz
        else:
            z0, z1 = (int(v) for v in z)
    except (TypeError, ValueError):
        raise InvalidParameterError(
            f"cannot read z slab {z!r}; use 'z0:z1' (e.g. 10:20) with rows z0 <= z < z1"
        ) from None
    if not 0 <= z0 < z1 <= nz:
        raise InvalidParameterError(
            f"z slab {z0}:{z1} is outside the volume's rows [0, {nz}); use 0 <= z0 < z1 <= {nz}"
        )
    return z0, z1


def _read_step(series: TimeSeries, step: int, z0: int, z1: int) -> np.ndarray:
    # Looked up at each call (the crash-safety tests slow it down to catch partial exports).
    return series.read([step], z0, z1)[0]
