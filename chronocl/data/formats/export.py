"""Export time steps of a series for other tools: ParaView (.vti + .pvd), numpy (.npy), raw.

- ``vti``: a folder OUT holding ``<stem>_t{step:05d}.vti`` per step and ``<stem>.pvd``,
  a ParaView collection that opens the files as one time series (``<stem>`` is OUT's
  name without suffix). Each step's values are the point array ``value``.
- ``npy``: one file OUT, a (W, Z, Y, X) array of the selected steps.
- ``raw``: a folder OUT holding headerless ``<stem>_t{step:05d}.raw`` files (x fastest,
  little-endian) and ``<stem>.json`` with dims, dtype, endianness and spacing, so
  ``chronocl ingest 'OUT/<stem>_t*.raw' --dims NX NY NZ ...`` reads them back.

Outputs appear only when complete (written to a temporary sibling, then renamed).
A z slab ("z0:z1") exports only those z rows; .vti files then carry the slab's origin.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from chronocl.core.atomic import atomic_directory, atomic_file
from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.core.paths import check_output
from chronocl.core.progress import track
from chronocl.core.selection import parse_selection
from chronocl.data.formats.vti import write_vti
from chronocl.data.series import TimeSeries

FORMATS = ("vti", "npy", "raw")
VTI_ARRAY = "value"


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
    from chronocl.core.paths import check_apart

    check_apart(out, [series.path])  # never onto, into or around the input
    kind = str(fmt).lower().lstrip(".")
    if kind not in FORMATS:
        raise UnknownNameError(f"unknown export format {fmt!r}; choose one of {', '.join(FORMATS)}")
    steps = parse_selection(window, series.n_steps).steps
    z0, z1 = parse_slab(z, series.shape[1])
    target = check_output(out, overwrite)
    if kind == "npy":
        return [_export_npy(series, target, steps, z0, z1, overwrite, progress)]
    if kind == "vti":
        return _export_vti(series, target, steps, z0, z1, overwrite, progress)
    return _export_raw(series, target, steps, z0, z1, overwrite, progress)


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


def _stem(target: Path) -> str:
    return target.stem or target.name


def _step_name(stem: str, step: int, suffix: str) -> str:
    return f"{stem}_t{step:05d}{suffix}"


def _read_step(series: TimeSeries, step: int, z0: int, z1: int) -> np.ndarray:
    return series.read([step], z0, z1)[0]


def _export_npy(series, target, steps, z0, z1, overwrite, progress) -> Path:
    shape = (len(steps), z1 - z0, *series.shape[2:])
    with atomic_file(target, overwrite) as tmp:
        out = np.lib.format.open_memmap(tmp, mode="w+", dtype=series.dtype, shape=shape)
        try:
            for i, s in enumerate(track(steps, len(steps), "exporting .npy", progress)):
                out[i] = _read_step(series, s, z0, z1)
            out.flush()
        finally:
            del out
    return target


def _export_vti(series, target, steps, z0, z1, overwrite, progress) -> list[Path]:
    stem = _stem(target)
    dz = series.spacing[0]
    names = [_step_name(stem, s, ".vti") for s in steps]
    with atomic_directory(target, overwrite) as tmp:
        tmp.mkdir(parents=True)
        for s, name in zip(
            track(steps, len(steps), "exporting .vti", progress), names, strict=True
        ):
            write_vti(
                tmp / name,
                {VTI_ARRAY: _read_step(series, s, z0, z1)},
                spacing=series.spacing,
                origin=(z0 * dz, 0.0, 0.0),
            )
        entries = "\n".join(
            f'    <DataSet timestep="{_time_value(series, s)}" group="" part="0" '
            f"file={quoteattr(name)}/>"
            for s, name in zip(steps, names, strict=True)
        )
        pvd = (
            '<?xml version="1.0"?>\n'
            '<VTKFile type="Collection" version="1.0" byte_order="LittleEndian">\n'
            "  <Collection>\n"
            f"{entries}\n"
            "  </Collection>\n"
            "</VTKFile>\n"
        )
        (tmp / f"{stem}.pvd").write_text(pvd, encoding="utf-8")
    return [target / f"{stem}.pvd", *(target / n for n in names)]


def _time_value(series: TimeSeries, step: int) -> str:
    """The step's time label when it is a number, else the step index."""
    label = series.times[step] if step < len(series.times) else step
    if isinstance(label, bool) or not isinstance(label, int | float):
        return str(step)
    return repr(label)


def _export_raw(series, target, steps, z0, z1, overwrite, progress) -> list[Path]:
    stem = _stem(target)
    names = [_step_name(stem, s, ".raw") for s in steps]
    little = series.dtype.newbyteorder("<")
    _, _, ny, nx = series.shape
    dz, dy, dx = series.spacing
    dims = [nx, ny, z1 - z0]
    sidecar = {
        "format": "chronocl.raw",
        "version": 1,
        "dims": dims,
        "dims_order": "x y z (x fastest)",
        "dtype": series.dtype.name,
        "endian": "little",
        "spacing": {"x": dx, "y": dy, "z": dz},
        "origin": {"x": 0.0, "y": 0.0, "z": z0 * dz},
        "z_slab": [z0, z1],
        "steps": list(steps),
        "times": [series.times[s] for s in steps],
        "files": names,
        "ingest": (
            f"chronocl ingest '{stem}_t*.raw' -o {stem}.zarr --dims {nx} {ny} {z1 - z0} "
            f"--dtype {series.dtype.name} --endian little --spacing {dx!r} {dy!r} {dz!r}"
        ),
    }
    with atomic_directory(target, overwrite) as tmp:
        tmp.mkdir(parents=True)
        for s, name in zip(
            track(steps, len(steps), "exporting .raw", progress), names, strict=True
        ):
            data = np.ascontiguousarray(_read_step(series, s, z0, z1), dtype=little)
            with open(tmp / name, "wb") as f:
                f.write(memoryview(data.reshape(-1).view(np.uint8)))
        (tmp / f"{stem}.json").write_text(json.dumps(sidecar, indent=2) + "\n", encoding="utf-8")
    return [target / f"{stem}.json", *(target / n for n in names)]
