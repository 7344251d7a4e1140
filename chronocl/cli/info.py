"""`chronocl info`: the summary of a series or chronovolume store, as text or JSON."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import AnonOpt, StorageOpt, out, print_summary, series_store


def info(
    store: Annotated[
        str,
        typer.Argument(
            metavar="STORE",
            help="A chronocl series or chronovolume store, local or at an http(s):// or s3:// URL.",
        ),
    ],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Show shape, dtype, value range, steps, chunking and size on disk.

    Example: chronocl info vortex.zarr --json
    """
    from chronocl.core.errors import StoreFormatError
    from chronocl.data.chronovolume import Chronovolume
    from chronocl.data.series import open_series

    store, storage_options = series_store(store, anon, storage_option)
    try:
        summary = open_series(store, storage_options=storage_options).describe()
    except StoreFormatError as as_series:
        try:  # read whole, as everywhere: a damaged chunk is reported, never shown as zeros
            cv = Chronovolume.load(store, storage_options)
        except StoreFormatError as as_cv:
            # Neither: say what each reading found, the series' first (what most stores are).
            raise StoreFormatError(
                f"{str(store)!r} is neither a series store nor a chronovolume: as a series, "
                f"{_reason(as_series, store)}; as a chronovolume, {_reason(as_cv, store)}"
            ) from None
        summary = {
            "chronovolume": str(store),
            "dims (x, y, z)": list(cv.dims),
            "shape (Z, Y, X)": list(cv.shape),
            **cv.metadata,
        }
    if as_json:
        out.print_json(json.dumps(summary, default=str))
    else:
        print_summary(summary)


def _reason(exc: Exception, store: Path | str) -> str:
    """An error's message without the store's name it starts with."""
    text = str(exc)
    for prefix in (repr(str(store)), str(store)):
        if text.startswith(prefix):
            return text[len(prefix) :].strip(" :")
    return text
