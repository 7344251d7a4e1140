"""Ingest time steps into a chronocl store with the reader the registry picks for them.

Readers (`chronocl.data.formats.registry.READERS`): raw files (one per step), a .npy, NetCDF /
HDF5, TIFF stacks, an OME-Zarr image. Everything is checked before the first byte is written
(options, sizes, existence), statistics are computed while writing, and the store is written
to a temporary sibling that is renamed only when complete. ``magnitude`` stores the magnitude
of two or three NetCDF variables or inputs; ``variables`` several NetCDF variables in one store
(`chronocl.data.variables`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from chronocl.core.errors import InputNotFoundError, InvalidParameterError, UnknownNameError
from chronocl.core.paths import check_apart, check_output
from chronocl.data.formats.contract import COMMON_OPTIONS, Reader
from chronocl.data.formats.registry import READERS, recognise
from chronocl.data.inputs import NO_INPUTS
from chronocl.data.remote_store import is_url
from chronocl.data.remote_write import remote_output
from chronocl.data.series import open_series, write_steps
from chronocl.data.timeseries import TimeSeries
from chronocl.data.variables import magnitude_steps, split_names

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
    *,
    flags: dict[str, str] | None = None,
    **options: object,
) -> TimeSeries:
    """Ingest with the reader for `fmt` (``auto``: by file type; raw files need dims=).

    `flags` names the command-line option an option came from where it is not ``--key``
    (``times`` read by ``--times-from-meta``), for the message that refuses it. `out` may be
    an s3:// URL (``storage_options=`` for s3fs): the store is written locally, then published
    whole, root metadata last (`chronocl.data.remote_write`); the series returned reads it there.

    ``magnitude="u,v,w"`` names variables of the one NetCDF input; with no `inputs` it names
    two or three raw / npy / TIFF inputs (paths or globs) of one shape instead, whose magnitude
    is stored.
    """
    storage_options = options.pop("storage_options", None)
    if is_url(str(out)):
        with remote_output(str(out), bool(options.get("overwrite")), storage_options) as local:
            ingest(inputs, local, fmt, flags=flags, **options)
        return open_series(str(out), storage_options=storage_options)
    check_apart(out, inputs)  # never onto, into or around an input
    if fmt not in FORMATS:
        raise UnknownNameError(f"unknown format {fmt!r}; choose one of {', '.join(FORMATS)}")
    if not inputs and options.get("magnitude"):
        return _component_magnitude(out, fmt, options)
    if not inputs:
        raise InputNotFoundError(NO_INPUTS)
    reader = READERS[detect_format(inputs) if fmt == "auto" else fmt]
    if options.get("magnitude") and reader.name != "netcdf":
        raise InvalidParameterError(
            f"--magnitude with {reader.name} input names the component inputs themselves: "
            "give them as --magnitude 'u*.raw,v*.raw,w*.raw' and no other inputs"
        )
    _reader_options(reader, options, flags or {})
    if reader.single and len(inputs) != 1:
        raise InvalidParameterError(f"{reader.name} input is one file; got {len(inputs)}")
    return reader.read(inputs[0] if reader.single else inputs, out, **options)


def _reader_options(reader: Reader, options: dict, flags: dict[str, str] | None = None) -> None:
    """Drop the common options `reader` does not take; refuse others meant for other readers."""
    for key in set(options) & set(COMMON_OPTIONS) - set(reader.common):
        del options[key]  # e.g. nan_fill for an OME-Zarr image, which is copied as it is
    for key, takers in _OPTIONS.items():
        if key in options and reader not in takers:
            value = options.pop(key)
            if value not in (None, takers[0].options[key]):
                flag = (flags or {}).get(key, "--" + key.replace("_", "-"))
                names = "/".join(r.name for r in takers)
                raise InvalidParameterError(f"{flag} applies to {names} input, not {reader.name}")


def _component_magnitude(out: str | os.PathLike, fmt: str, options: dict) -> TimeSeries:
    """The magnitude of two or three inputs (paths or globs), each read by its reader."""
    components = split_names(str(options.pop("magnitude")), "--magnitude", (2, 3))
    check_apart(out, components)
    reader = READERS[detect_format(components[:1]) if fmt == "auto" else fmt]
    if reader.steps is None:
        raise InvalidParameterError(
            f"--magnitude takes raw, npy or TIFF inputs (or NetCDF variables), not {reader.name}"
        )
    common = {k: options.pop(k) for k in COMMON_OPTIONS if k in options}
    _reader_options(reader, options)
    check_output(out, bool(common.get("overwrite")))
    parts = [reader.steps(c if reader.single else [c], **options) for c in components]
    return write_steps(out, magnitude_steps(parts, components), **common)
