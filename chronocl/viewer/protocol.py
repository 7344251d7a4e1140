"""The viewer's WebSocket protocol: message schemas and their validation.

Client -> server messages are JSON objects of at most `MAX_MESSAGE_BYTES`, each with a
`type` and an optional request `id` (echoed in replies and frames):

    open       {"dataset": index or name}               switch data set (defaults reset)
    update     camera, views, window, data_tf, time_tf,  any subset; the server merges it
               enhance, threshold, clip, size, quality,  into the client's state and renders
               background, outline                       the newest state only
    probe      {"view", "x", "y"}                       x, y in [0, 1] of the panel, top-left 0
    histogram  {"range": [lo, hi]}                       normalised values u, for TF zoom
    save       {"what": "image" | "chronovolume", "view"}

Every field is checked against its schema: unknown fields, wrong types and out-of-range values
(numbers must be finite; data values must fit float32, ranges need lo < hi) raise
`ProtocolError` naming the field; so do messages nested deeper than `MAX_DEPTH`, refused
before decoding. The server answers {"type": "error", "id", "message"} and keeps serving.
Server -> client: JSON text messages (info, dataset, histogram, probe, download, error) and
binary frames (`pack_frame`: a 4-byte big-endian header length, a JSON
header, then the images' bytes back to back).
"""

from __future__ import annotations

import json
import math
import re
import struct
from dataclasses import dataclass

from chronocl import modes
from chronocl.core.errors import InvalidParameterError

MAX_MESSAGE_BYTES = 64 * 1024
MAX_DEPTH = 8  # the deepest message (update.data_tf.points[i][j]) nests 4 containers
FLOAT32_MAX = 3.4028234663852886e38
MAX_VIEWS = 4
MAX_TF_POINTS = 64
MIN_PANEL, MAX_PANEL = 64, 1024


class ProtocolError(InvalidParameterError):
    """A viewer message that is malformed, oversized, or has unknown or out-of-range fields."""


# --------------------------------------------------------------------------- schema primitives


@dataclass(frozen=True)
class Num:
    lo: float
    hi: float

    def check(self, value: object, path: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ProtocolError(f"{path} must be a number, got {_show(value)}")
        try:
            x = float(value)
        except OverflowError:  # an int beyond any float
            x = math.inf
        if not math.isfinite(x) or not self.lo <= x <= self.hi:
            raise ProtocolError(f"{path} is {_show(value)}; it must lie in [{self.lo}, {self.hi}]")
        return x


@dataclass(frozen=True)
class Int:
    lo: int
    hi: int

    def check(self, value: object, path: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProtocolError(f"{path} must be an integer, got {_show(value)}")
        if not self.lo <= value <= self.hi:
            raise ProtocolError(f"{path} is {value}; it must lie in [{self.lo}, {self.hi}]")
        return value


@dataclass(frozen=True)
class Enum:
    values: tuple[str, ...]

    def check(self, value: object, path: str) -> str:
        if not isinstance(value, str) or value not in self.values:
            raise ProtocolError(f"{path} is {_show(value)}; choose one of {', '.join(self.values)}")
        return value


@dataclass(frozen=True)
class Bool:
    def check(self, value: object, path: str) -> bool:
        if not isinstance(value, bool):
            raise ProtocolError(f"{path} must be true or false, got {_show(value)}")
        return value


@dataclass(frozen=True)
class Name:
    """A data set named by its index in the server's list or by its name (never a path)."""

    def check(self, value: object, path: str) -> int | str:
        if isinstance(value, int) and not isinstance(value, bool):
            return Int(0, 1000).check(value, path)
        if isinstance(value, str) and 0 < len(value) <= 200:
            return value
        raise ProtocolError(f"{path} must be a data set index or name, got {_show(value)}")


@dataclass(frozen=True)
class List:
    item: object
    min_len: int
    max_len: int

    def check(self, value: object, path: str) -> list:
        if not isinstance(value, list):
            raise ProtocolError(f"{path} must be a list, got {_show(value)}")
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
            raise ProtocolError(f"{path} must be an object, got {_show(value)}")
        unknown = sorted(set(value) - set(self.fields))
        if unknown:
            raise ProtocolError(
                f"{path} has unknown field {unknown[0]!r}; allowed: {', '.join(self.fields)}"
            )
        missing = sorted(self.required - set(value))
        if missing:
            raise ProtocolError(f"{path} is missing the field {missing[0]!r}")
        return {k: self.fields[k].check(v, f"{path}.{k}") for k, v in value.items()}


def _show(value: object) -> str:
    text = json.dumps(value) if _jsonable(value) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _jsonable(value: object) -> bool:
    try:
        json.dumps(value)
    except (TypeError, ValueError):
        return False
    return True


# --------------------------------------------------------------------------- messages

ORDERS = ("forward", "backward")
TIME_COLORS = ("rgb", "warm-cool", "luminance", "white")
TIME_ALPHAS = ("constant", "hat", "inverted-hat")
ENHANCE_KINDS = ("none", "edge", "silhouette")

CAMERA = Obj(
    {
        "azimuth": Num(-1e6, 1e6),
        "elevation": Num(-89.9, 89.9),
        "zoom": Num(0.1, 20.0),
        "fov": Num(5.0, 90.0),
        "projection": Enum(("perspective", "orthographic")),
    }
)
VIEW = Obj({"mode": Enum(modes.names()), "order": Enum(ORDERS)}, frozenset({"mode"}))
WINDOW = Obj(
    {"t0": Int(0, 10**7), "t1": Int(1, 10**7), "stride": Int(1, 10**7)},
    frozenset({"t0", "t1"}),
)
DATA_TF = Obj(
    {
        "points": List(List(Num(0.0, 1.0), 5, 5), 1, MAX_TF_POINTS),
        "value_range": Nullable(Range(Num(-FLOAT32_MAX, FLOAT32_MAX))),
    },
    frozenset({"points"}),
)
TIME_TF = Obj(
    {
        "color": Enum(TIME_COLORS),
        "focus": Num(0.0, 1.0),
        "falloff": Num(0.01, 10.0),
        "alpha": Enum(TIME_ALPHAS),
        "value": Num(0.0, 1.0),
        "center": Num(0.0, 1.0),
        "width": Num(0.01, 2.0),
        "floor": Num(0.0, 1.0),
        "positions": Enum(("relative", "absolute")),
    }
)
ENHANCE = Obj(
    {
        "kind": Enum(ENHANCE_KINDS),
        "k0": Num(0.0, 10.0),
        "k1": Num(0.0, 100.0),
        "k2": Num(0.0, 10.0),
    }
)
CLIP = Nullable(
    Obj({"normal": List(Num(-1.0, 1.0), 3, 3), "offset": Num(-1.0, 1.0)}, frozenset({"normal"}))
)
ID = Int(0, 2**53)

MESSAGES: dict[str, Obj] = {
    "open": Obj({"type": Enum(("open",)), "id": ID, "dataset": Name()}, frozenset({"dataset"})),
    "update": Obj(
        {
            "type": Enum(("update",)),
            "id": ID,
            "camera": CAMERA,
            "views": List(VIEW, 1, MAX_VIEWS),
            "window": WINDOW,
            "data_tf": DATA_TF,
            "time_tf": TIME_TF,
            "enhance": ENHANCE,
            "threshold": Num(0.0, 0.99),
            "clip": CLIP,
            "size": List(Int(MIN_PANEL, MAX_PANEL), 2, 2),
            "quality": Enum(("preview", "full")),
            "background": Enum(("black", "white")),
            "outline": Bool(),
        }
    ),
    "probe": Obj(
        {
            "type": Enum(("probe",)),
            "id": ID,
            "view": Int(0, MAX_VIEWS - 1),
            "x": Num(0.0, 1.0),
            "y": Num(0.0, 1.0),
        },
        frozenset({"x", "y"}),
    ),
    "histogram": Obj(
        {"type": Enum(("histogram",)), "id": ID, "range": Range(Num(0.0, 1.0))},
        frozenset({"range"}),
    ),
    "save": Obj(
        {
            "type": Enum(("save",)),
            "id": ID,
            "what": Enum(("image", "chronovolume")),
            "view": Int(0, MAX_VIEWS - 1),
        },
        frozenset({"what"}),
    ),
}


def _reject_constant(name: str) -> float:
    raise ProtocolError(f"{name} is not allowed in a message; send finite numbers")


_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)
_BRACKETS = re.compile(r"[\[\]{}]")


def too_deep(text: str, limit: int = MAX_DEPTH) -> bool:
    """Whether the JSON text nests arrays and objects deeper than `limit` (strings skipped;
    a cheap scan before decoding, which recurses once per level)."""
    depth = 0
    for m in _BRACKETS.finditer(_STRINGS.sub("", text)):
        if m.group() in "[{":
            depth += 1
            if depth > limit:
                return True
        else:
            depth -= 1
    return False


def _decode(text: str) -> object:
    """json.loads without NaN/Infinity and without deep nesting (ProtocolError, ValueError)."""
    if too_deep(text):
        raise ProtocolError(
            f"message nests arrays or objects more than {MAX_DEPTH} deep; send a flat message"
        )
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except RecursionError:  # the scan above should have caught it
        raise ProtocolError("message nests too deep; send a flat message") from None


def request_id(text: object) -> int | None:
    """The `id` of a message, if it has a usable one (for error replies to bad messages)."""
    if not isinstance(text, str) or len(text) > MAX_MESSAGE_BYTES or too_deep(text):
        return None
    try:  # NaN and Infinity elsewhere in the message do not hide its id
        msg = json.loads(text, parse_constant=lambda name: None)
    except (ValueError, RecursionError):
        return None
    rid = msg.get("id") if isinstance(msg, dict) else None
    return rid if isinstance(rid, int) and not isinstance(rid, bool) and 0 <= rid <= 2**53 else None


def parse_message(text: object) -> dict:
    """Decode and validate one client message; raises ProtocolError naming what is wrong."""
    if isinstance(text, bytes | bytearray):
        raise ProtocolError("binary messages are not accepted; send JSON text")
    if not isinstance(text, str):
        raise ProtocolError("empty message; send a JSON object")
    if len(text) > MAX_MESSAGE_BYTES:  # characters; a cheap bound before decoding
        raise ProtocolError(
            f"message of {len(text)} characters is over the limit of {MAX_MESSAGE_BYTES}"
        )
    if len(text.encode()) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message is over the limit of {MAX_MESSAGE_BYTES} bytes")
    try:
        msg = _decode(text)
    except ProtocolError:
        raise
    except ValueError as exc:
        raise ProtocolError(f"message is not valid JSON ({exc})") from None
    if not isinstance(msg, dict):
        raise ProtocolError("message must be a JSON object with a 'type'")
    kind = msg.get("type")
    if not isinstance(kind, str) or kind not in MESSAGES:
        raise ProtocolError(
            f"unknown message type {_show(kind)}; choose one of {', '.join(MESSAGES)}"
        )
    return MESSAGES[kind].check(msg, kind)


def pack_frame(header: dict, images: list[bytes]) -> bytes:
    """A binary frame: header length (uint32, big-endian), JSON header, image bytes in order.

    The header lists each image's byte length under `views[i].bytes`.
    """
    head = json.dumps(header, separators=(",", ":")).encode()
    return b"".join([struct.pack(">I", len(head)), head, *images])


def unpack_frame(data: bytes) -> tuple[dict, list[bytes]]:
    """The inverse of `pack_frame` (for tests and the benchmark)."""
    (n,) = struct.unpack(">I", data[:4])
    header = json.loads(data[4 : 4 + n])
    images, at = [], 4 + n
    for view in header["views"]:
        images.append(data[at : at + view["bytes"]])
        at += view["bytes"]
    return header, images
