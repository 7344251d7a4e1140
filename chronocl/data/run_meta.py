"""What a simulation's JSON says about its raw output (`ingest --meta FILE`): the volume's size,
its voxel spacing, the values' type and byte order, and the steps' times
(`chronocl.core.times_meta`), each where the file gives it.

Looked for at any depth, under these keys only (nothing is guessed from others):

- size, x first: ``dims``, ``dimensions``, ``grid_size``, ``resolution`` (three integers), or
  ``nx``, ``ny``, ``nz`` side by side;
- spacing, x first: ``spacing``, ``voxel_size``, ``grid_spacing`` (three numbers, or an object
  with x, y, z), or ``dx``, ``dy``, ``dz`` side by side;
- type: ``dtype``, ``data_type``, ``datatype``, ``precision`` (float32, float, single, f4,
  <f4, double, uint16, ...; a numpy code with a byte order gives that too);
- byte order: ``endian``, ``endianness``, ``byte_order``, ``byteorder`` (little, big, <, >).

A field given twice with different values is ambiguous: the error names both places.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.core.times_meta import MetaTimes, finite, load_meta, objects_in, times_from_meta
from chronocl.data.metadata import SUPPORTED_DTYPES

DIMS_KEYS = ("dims", "dimensions", "grid_size", "resolution")
SPACING_KEYS = ("spacing", "voxel_size", "grid_spacing")
DTYPE_KEYS = ("dtype", "data_type", "datatype", "precision")
ENDIAN_KEYS = ("endian", "endianness", "byte_order", "byteorder")
DTYPE_WORDS = {
    "float": "float32",
    "single": "float32",
    "real32": "float32",
    "real": "float32",
    "double": "float64",
    "real64": "float64",
}
ENDIAN_WORDS = {"little": "little", "little-endian": "little", "<": "little", "le": "little"}
ENDIAN_WORDS.update({"big": "big", "big-endian": "big", ">": "big", "be": "big"})


@dataclass(frozen=True)
class RunMeta:
    """The fields a metadata file gives (None where it gives none) and where each was found."""

    dims: tuple[int, int, int] | None = None
    spacing: tuple[float, float, float] | None = None
    dtype: str | None = None
    endian: str | None = None
    times: MetaTimes | None = None
    found: dict[str, str] = field(default_factory=dict)

    def layout(self) -> dict[str, object]:
        """dims, spacing, dtype and endian, those the file gives."""
        fields = {"dims": self.dims, "spacing": self.spacing}
        fields.update(dtype=self.dtype, endian=self.endian)
        return {k: v for k, v in fields.items() if v is not None}


def read_run_meta(path: str | Path, given: frozenset[str] = frozenset()) -> RunMeta:
    """Every field `path` gives (see the module docstring), checked, except those in `given`
    (flags gave them: the file's are not read, so neither its doubts nor its errors matter;
    "times" and "time_unit"). Under a key that holds something else (a camera's
    "resolution", a particle list's "dtype") a value that is not the field is passed over
    where another place gives the field; where none does, its error is the answer."""
    p = Path(path)
    root = load_meta(p, "--meta")
    found: dict[str, str] = {}
    picked: dict[str, object] = {}
    errors: dict[str, InvalidParameterError] = {}

    def note(name: str, parse, value: object, where: str) -> None:
        if name in given:
            return
        try:
            parsed = parse(value, f"{p}:{where}")
        except InvalidParameterError as exc:
            errors.setdefault(name, exc)
            return
        if name == "dtype":
            parsed, order = parsed
            if order is not None:
                note("endian", lambda v, w: v, order, where)
        if name in picked and picked[name] != parsed:
            raise InvalidParameterError(
                f"{p} gives two {name}: {found[name]} and {p}:{where}; give --{name} to choose"
            )
        if name not in picked:
            picked[name], found[name] = parsed, f"{p}:{where}"

    for where, obj in objects_in(root, ""):
        for key in DIMS_KEYS:
            if key in obj:
                note("dims", _dims, obj[key], f"{where}{key}")
        if all(k in obj for k in ("nx", "ny", "nz")):
            note("dims", _dims, [obj["nx"], obj["ny"], obj["nz"]], f"{where}nx/ny/nz")
        for key in SPACING_KEYS:
            if key in obj:
                note("spacing", _spacing, obj[key], f"{where}{key}")
        if all(finite(obj.get(k)) is not None for k in ("dx", "dy", "dz")):
            note("spacing", _spacing, [obj["dx"], obj["dy"], obj["dz"]], f"{where}dx/dy/dz")
        for key in DTYPE_KEYS:
            if isinstance(obj.get(key), str):
                note("dtype", _dtype, obj[key], f"{where}{key}")
        for key in ENDIAN_KEYS:
            if isinstance(obj.get(key), str):
                note("endian", _endian, obj[key], f"{where}{key}")
    for name, exc in errors.items():
        if name not in picked:
            raise exc
    times = None if "times" in given else times_from_meta(p, required=False, root=root)
    if times is not None:
        found["times"] = times.found
    return RunMeta(times=times, found=found, **picked)  # type: ignore[arg-type]


def _dims(value: object, where: str) -> tuple[int, int, int]:
    ok = isinstance(value, list) and len(value) == 3
    ok = ok and all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in value)
    if not ok:
        raise InvalidParameterError(
            f"{where} is {value!r}, not three positive integers NX NY NZ; give --dims"
        )
    return tuple(value)  # type: ignore[return-value]


def _spacing(value: object, where: str) -> tuple[float, float, float]:
    if isinstance(value, dict) and all(k in value for k in "xyz"):
        value = [value["x"], value["y"], value["z"]]
    numbers = [finite(v) for v in value] if isinstance(value, list) and len(value) == 3 else []
    if len(numbers) != 3 or any(v is None or v <= 0 for v in numbers):
        raise InvalidParameterError(
            f"{where} is {value!r}, not three positive spacings DX DY DZ; give --spacing"
        )
    return tuple(numbers)  # type: ignore[return-value]


def _dtype(text: str, where: str) -> tuple[str, str | None]:
    """(the type, the byte order a numpy code such as '>f4' names, else None)."""
    word = DTYPE_WORDS.get(text.strip().lower(), text.strip())
    word = word if word[:1] in "<>=|" else word.lower()  # Float32, FLOAT64
    try:
        dt = np.dtype(word)
    except TypeError:
        dt = None
    if dt is None or dt.name not in SUPPORTED_DTYPES:
        raise InvalidParameterError(
            f"{where} is {text!r}, not a type chronocl reads ({', '.join(SUPPORTED_DTYPES)}); "
            "give --dtype"
        )
    order = {"<": "little", ">": "big"}.get(word[:1]) if dt.itemsize > 1 else None
    return dt.name, order


def _endian(text: str, where: str) -> str:
    order = ENDIAN_WORDS.get(text.strip().lower())
    if order is None:
        raise InvalidParameterError(f"{where} is {text!r}, not little or big; give --endian")
    return order
