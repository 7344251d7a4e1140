"""The schema primitives the viewer's messages are checked with.

Each primitive's `check(value, path)` returns the value (numbers as float or int) or raises
`ProtocolError` naming the field by its path, e.g. ``update.camera.zoom is 50; it must lie in
[0.1, 20.0]``. `chronocl.viewer.protocol` builds the message schemas from them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from chronocl.core.errors import InvalidParameterError

FLOAT32_MAX = 3.4028234663852886e38


class ProtocolError(InvalidParameterError):
    """A viewer message that is malformed, oversized, or has unknown or out-of-range fields."""


@dataclass(frozen=True)
class Num:
    lo: float
    hi: float

    def check(self, value: object, path: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ProtocolError(f"{path} must be a number, got {show(value)}")
        try:
            x = float(value)
        except OverflowError:  # an int beyond any float
            x = math.inf
        if not math.isfinite(x) or not self.lo <= x <= self.hi:
            raise ProtocolError(f"{path} is {show(value)}; it must lie in [{self.lo}, {self.hi}]")
        return x


@dataclass(frozen=True)
class Int:
    lo: int
    hi: int

    def check(self, value: object, path: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProtocolError(f"{path} must be an integer, got {show(value)}")
        if not self.lo <= value <= self.hi:
            raise ProtocolError(f"{path} is {value}; it must lie in [{self.lo}, {self.hi}]")
        return value


@dataclass(frozen=True)
class Enum:
    values: tuple[str, ...]

    def check(self, value: object, path: str) -> str:
        if not isinstance(value, str) or value not in self.values:
            raise ProtocolError(f"{path} is {show(value)}; choose one of {', '.join(self.values)}")
        return value


@dataclass(frozen=True)
class Bool:
    def check(self, value: object, path: str) -> bool:
        if not isinstance(value, bool):
            raise ProtocolError(f"{path} must be true or false, got {show(value)}")
        return value


@dataclass(frozen=True)
class Name:
    """A data set named by its index in the server's list or by its name (never a path)."""

    def check(self, value: object, path: str) -> int | str:
        if isinstance(value, int) and not isinstance(value, bool):
            return Int(0, 1000).check(value, path)
        if isinstance(value, str) and 0 < len(value) <= 200:
            return value
        raise ProtocolError(f"{path} must be a data set index or name, got {show(value)}")


@dataclass(frozen=True)
class Text:
    """A string of 1 to `max_len` characters."""

    max_len: int

    def check(self, value: object, path: str) -> str:
        if not isinstance(value, str) or not 0 < len(value) <= self.max_len:
            raise ProtocolError(f"{path} must be a text of 1 to {self.max_len} characters")
        return value


@dataclass(frozen=True)
class Version:
    """The version number of a saved format: exactly `current`."""

    current: int
    what: str

    def check(self, value: object, path: str) -> int:
        if value != self.current or isinstance(value, bool):
            raise ProtocolError(
                f"{path} is {show(value)}: this chronocl reads {self.what} version "
                f"{self.current}; save it again with this version"
            )
        return self.current


@dataclass(frozen=True)
class List:
    item: object
    min_len: int
    max_len: int

    def check(self, value: object, path: str) -> list:
        if not isinstance(value, list):
            raise ProtocolError(f"{path} must be a list, got {show(value)}")
        if not self.min_len <= len(value) <= self.max_len:
            n = (
                str(self.min_len)
                if self.min_len == self.max_len
                else f"{self.min_len} to {self.max_len}"
            )
            raise ProtocolError(f"{path} has {len(value)} entries; give {n}")
        return [self.item.check(v, f"{path}[{i}]") for i, v in enumerate(value)]  # type: ignore[attr-defined]


@dataclass(frozen=True)
class Range:
    """[lo, hi]: two numbers with lo < hi whose span, and its reciprocal, are finite float32
    (values are normalised as (v - lo) / (hi - lo) in float32)."""

    item: Num

    def check(self, value: object, path: str) -> list:
        lo, hi = List(self.item, 2, 2).check(value, path)
        span = hi - lo
        if not span > 0:
            raise ProtocolError(f"{path} is [{lo:g}, {hi:g}]; it must have lo < hi")
        if span > FLOAT32_MAX or span < 1.0 / FLOAT32_MAX:
            raise ProtocolError(
                f"{path} spans {span:g}; hi - lo must lie in [{1.0 / FLOAT32_MAX:.3g}, "
                f"{FLOAT32_MAX:.3g}] (float32)"
            )
        return [lo, hi]


@dataclass(frozen=True)
class Nullable:
    inner: object

    def check(self, value: object, path: str) -> object:
        return None if value is None else self.inner.check(value, path)  # type: ignore[attr-defined]


@dataclass(frozen=True)
class Obj:
    fields: dict
    required: frozenset = frozenset()

    def check(self, value: object, path: str) -> dict:
        if not isinstance(value, dict):
            raise ProtocolError(f"{path} must be an object, got {show(value)}")
        unknown = sorted(set(value) - set(self.fields))
        if unknown:
            raise ProtocolError(
                f"{path} has unknown field {unknown[0]!r}; allowed: {', '.join(self.fields)}"
            )
        missing = sorted(self.required - set(value))
        if missing:
            raise ProtocolError(f"{path} is missing the field {missing[0]!r}")
        return {k: self.fields[k].check(v, f"{path}.{k}") for k, v in value.items()}


def show(value: object) -> str:
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."
