"""VTK XML ImageData (.vti) files, which ParaView and VTK open directly: volumes, chronovolumes
and series steps (one .vti per step and a .pvd collection that opens them as one time series).

The writer needs no VTK: a .vti is a small XML header followed by the arrays in
"appended raw" encoding (after the ``_`` marker, each array is a UInt64 byte
count then its little-endian bytes, x fastest). Arrays are point data on the
grid; (Z, Y, X) arrays are scalars and (Z, Y, X, C) arrays have C components.
Files are written to a temporary sibling and renamed when complete.

Spacing and origin are (x, y, z), x first, as everywhere in chronocl's API and in VTK.

An export of steps writes a folder OUT holding ``<stem>_t{step:05d}.vti`` per step, each with
the point array ``value``, and ``<stem>.pvd``; a z slab's files carry the slab's origin.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, BinaryIO
from xml.sax.saxutils import quoteattr

import numpy as np

from chronocl.core.atomic import atomic_directory, atomic_file
from chronocl.core.errors import InvalidParameterError
from chronocl.core.progress import track
from chronocl.data.formats.contract import Exporter, Output, StepExport

if TYPE_CHECKING:
    from chronocl.data.chronovolume import Chronovolume
    from chronocl.data.timeseries import TimeSeries

VTK_TYPES = {
    "int8": "Int8",
    "uint8": "UInt8",
    "int16": "Int16",
    "uint16": "UInt16",
    "int32": "Int32",
    "uint32": "UInt32",
    "int64": "Int64",
    "uint64": "UInt64",
    "float32": "Float32",
    "float64": "Float64",
}
VTI_ARRAY = "value"  # the point array of each exported step
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")
_HEADER = np.dtype("<u8")


def write_vti(
    path: str | os.PathLike,
    arrays: Mapping[str, np.ndarray],
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    origin: Sequence[float] = (0.0, 0.0, 0.0),
    overwrite: bool = False,
) -> Path:
    """Write `arrays` ({name: (Z, Y, X) or (Z, Y, X, C)}) as point data of one .vti file.

    `spacing` is (dx, dy, dz) and `origin` (ox, oy, oz), x first. Returns the path written.
    """
    named = _check_arrays(arrays)
    sp = _check_triple(spacing, "spacing", positive=True)
    org = _check_triple(origin, "origin", positive=False)
    nz, ny, nx = next(iter(named.values())).shape[:3]
    extent = f"0 {nx - 1} 0 {ny - 1} 0 {nz - 1}"

    lines = [
        '<?xml version="1.0"?>',
        '<VTKFile type="ImageData" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
        f'  <ImageData WholeExtent="{extent}" Origin="{_xyz(org)}" Spacing="{_xyz(sp)}">',
        f'    <Piece Extent="{extent}">',
        f'      <PointData Scalars="{next(iter(named))}">',
    ]
    offset = 0
    for name, a in named.items():
        comps = 1 if a.ndim == 3 else a.shape[3]
        lines.append(
            f'        <DataArray type="{VTK_TYPES[a.dtype.name]}" Name="{name}" '
            f'NumberOfComponents="{comps}" format="appended" offset="{offset}"/>'
        )
        offset += _HEADER.itemsize + a.nbytes
    lines += [
        "      </PointData>",
        "      <CellData>",
        "      </CellData>",
        "    </Piece>",
        "  </ImageData>",
        '  <AppendedData encoding="raw">',
        "   _",
    ]
    header = "\n".join(lines).encode("ascii")

    target = Path(path)
    with atomic_file(target, overwrite) as tmp, open(tmp, "wb") as f:
        f.write(header)
        for a in named.values():
            _write_block(f, a)
        f.write(b"\n  </AppendedData>\n</VTKFile>\n")
    return target


def save_chronovolume_vti(
    cv: Chronovolume, path: str | os.PathLike, overwrite: bool = False
) -> Path:
    """Write a chronovolume's ``rgba`` (premultiplied, 4 components) and ``t_index`` as a .vti."""
    arrays: dict[str, np.ndarray] = {"rgba": cv.float_rgba()}
    if cv.t_index is not None:
        arrays["t_index"] = np.asarray(cv.t_index, dtype=np.int32)
    return write_vti(path, arrays, spacing=cv.spacing, overwrite=overwrite)


def export_vti(job: StepExport) -> list[Path]:
    """Write each step as a .vti and the .pvd collection of them; the .pvd comes first."""
    series, target, steps = job.series, job.target, job.steps
    dz = series.spacing[2]
    names = [job.step_name(s, ".vti") for s in steps]
    with atomic_directory(target, job.overwrite) as tmp:
        tmp.mkdir(parents=True)
        for s, name in zip(
            track(steps, len(steps), "exporting .vti", job.progress), names, strict=True
        ):
            write_vti(
                tmp / name,
                {VTI_ARRAY: job.read(s)},
                spacing=series.spacing,
                origin=(0.0, 0.0, job.z0 * dz),
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
        (tmp / f"{job.stem}.pvd").write_text(pvd, encoding="utf-8")
    return [target / f"{job.stem}.pvd", *(target / n for n in names)]


def _time_value(series: TimeSeries, step: int) -> str:
    """The step's time label when it is a number, else the step index."""
    label = series.times[step] if step < len(series.times) else step
    if isinstance(label, bool) or not isinstance(label, int | float):
        return str(step)
    return repr(label)


def _check_arrays(arrays: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    if not arrays:
        raise InvalidParameterError("a .vti needs at least one array; none were given")
    out: dict[str, np.ndarray] = {}
    grid: tuple[int, ...] | None = None
    for name, value in arrays.items():
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise InvalidParameterError(
                f"array name {name!r} is not usable in a .vti; use letters, digits, '_', '.', '-'"
            )
        a = np.asarray(value)
        if a.dtype.name not in VTK_TYPES:
            raise InvalidParameterError(
                f"array {name!r} has type {a.dtype.name}; use one of {', '.join(VTK_TYPES)}"
            )
        if a.ndim not in (3, 4) or min(a.shape) < 1:
            raise InvalidParameterError(
                f"array {name!r} has shape {a.shape}; expected non-empty (Z, Y, X) or (Z, Y, X, C)"
            )
        if grid is None:
            grid = a.shape[:3]
        elif a.shape[:3] != grid:
            raise InvalidParameterError(
                f"array {name!r} has grid {a.shape[:3]} but the first array has {grid} (Z, Y, X)"
            )
        out[name] = a
    return out


def _check_triple(values: Sequence[float], what: str, positive: bool) -> tuple[float, ...]:
    try:
        t = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{what} {values!r} must be three numbers (x, y, z)") from None
    ok = len(t) == 3 and all(math.isfinite(v) and (v > 0 or not positive) for v in t)
    if not ok:
        need = "finite numbers > 0" if positive else "finite numbers"
        raise InvalidParameterError(f"{what} {list(t)} must be three {need} (x, y, z)")
    return t


def _xyz(xyz: Sequence[float]) -> str:
    return " ".join(repr(float(v)) for v in xyz)


def _write_block(f: BinaryIO, a: np.ndarray) -> None:
    """One appended block: UInt64 byte count, then the little-endian C-order bytes."""
    little = np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<"))
    f.write(np.array([little.nbytes], dtype=_HEADER).tobytes())
    f.write(memoryview(little.reshape(-1).view(np.uint8)))


OUTPUT = Output(".vti", "ParaView", save_chronovolume_vti)
EXPORTER = Exporter("vti", export_vti)
