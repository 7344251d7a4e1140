"""The formats chronocl reads and writes, listed once: ingest readers, chronovolume outputs and
step exporters. Each format module declares its own (see `chronocl.data.formats.contract`); the
fronts (`chronocl.data.ingest`, `chronocl.data.formats.outputs`, `chronocl.data.formats.export`)
choose here.
"""

from __future__ import annotations

import os
from pathlib import Path

from chronocl.data.chronovolume import Chronovolume
from chronocl.data.formats import netcdf, npy, omezarr, omezarr_chronovolume, raw, tiff, vti
from chronocl.data.formats.contract import Exporter, Output, Reader

# Each table in the order its entries are named in messages.
READERS: dict[str, Reader] = {m.READER.name: m.READER for m in (raw, npy, netcdf, tiff, omezarr)}
OUTPUTS: tuple[Output, ...] = (
    Output(".zarr", "chronocl", Chronovolume.save),  # chronocl's own; `Chronovolume.load` reads it
    omezarr_chronovolume.OUTPUT,
    vti.OUTPUT,
)
EXPORTERS: dict[str, Exporter] = {m.EXPORTER.name: m.EXPORTER for m in (vti, npy, raw)}


def recognise(path: Path) -> Reader | None:
    """The reader for inputs starting with `path`: the first that recognises it, else the one
    for unrecognised files (raw); None for a folder that no reader recognises."""
    for reader in READERS.values():
        if reader.recognises is not None and reader.recognises(path):
            return reader
    if path.is_dir():
        return None
    return next(r for r in READERS.values() if r.recognises is None)


def output_for(path: str | os.PathLike) -> Output | None:
    """The output whose suffix ends `path` (the longest: .ome.zarr before .zarr), else None."""
    name = str(path).lower().rstrip("/")
    matching = [o for o in OUTPUTS if name.endswith(o.suffix)]
    return max(matching, key=lambda o: len(o.suffix), default=None)
