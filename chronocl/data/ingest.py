"""Ingest time steps into a chronocl store with the reader the registry picks for them.

Readers (`chronocl.data.formats.registry.READERS`): raw files (one per step), a .npy, NetCDF /
HDF5, TIFF stacks, an OME-Zarr image. Everything is checked before the first byte is written
(options, sizes, existence), statistics are computed while writing, and the store is written
to a temporary sibling that is renamed only when complete.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from chronocl.core.errors import InputNotFoundError, InvalidParameterError, UnknownNameError
from chronocl.core.paths import check_apart
from chronocl.data.formats.contract import COMMON_OPTIONS
from chronocl.data.formats.registry import READERS, recognise
from chronocl.data.inputs import NO_INPUTS
from chronocl.data.timeseries import TimeSeries

FORMATS = ("auto", *READERS)
# Each reader's own options and the readers that take them: those of one reader first, then
# the shared ones (spacing), which is the order their misuse is reported in.
_OPTIONS = {
    key: [r for r in READERS.values() if key in r.options]
    for key in sorted(
        dict.fromkeys(k for r in READERS.values() for k in r.options),
        key=lambda k: sum(k in r.options for r in READERS.values()),
    )
}


def detect_format(inputs: Sequence[str | os.PathLike]) -> str:
    """The reader for these inputs, from the file type (a folder: OME-Zarr)."""
    first = Path(str(inputs[0]))
    reader = recognise(first)
    if reader is None:
        raise InvalidParameterError(
            f"{first} is a folder but not an OME-Zarr image; give files, or --format"
        )
    return reader.name


def ingest(
    inputs: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    fmt: str = "auto",
    **options: object,
) -> TimeSeries:
    """Ingest with the reader for `fmt` (``auto``: by file type; raw files need dims=)."""
    check_apart(out, inputs)  # never onto, into or around an input
    if fmt not in FORMATS:
        raise UnknownNameError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if not inputs:
        raise InputNotFoundError(NO_INPUTS)
    reader = READERS[detect_format(inputs) if fmt == "auto" else fmt]
    for key in set(options) & set(COMMON_OPTIONS) - set(reader.common):
        del options[key]  # e.g. nan_fill for an OME-Zarr image, which is copied as it is
    for key, takers in _OPTIONS.items():
        if key in options and reader not in takers:
            value = options.pop(key)
            if value not in (None, takers[0].options[key]):
                flag = "--" + key.replace("_", "-")
                names = "/".join(r.name for r in takers)
                raise InvalidParameterError(f"{flag} applies to {names} input, not {reader.name}")
    if reader.single and len(inputs) != 1:
        raise InvalidParameterError(f"{reader.name} input is one file; got {len(inputs)}")
    return reader.read(inputs[0] if reader.single else inputs, out, **options)
