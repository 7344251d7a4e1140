"""Transfer functions: data TF (value -> RGBA), time TF (time position -> RGB, alpha), modulation.

A voxel's value u in [0, 1] at step k with time position p_k gets
colour c_k = rgb_d(u) * rgb_t(p_k) and opacity α_k = a_d(u) * a_t(p_k) * e_k
(docs/semantics.md). The data TF is piecewise linear over control points and
is sampled into a LUT that is evaluated with linear interpolation between
entries; the engines all use that LUT, so they agree to rounding. A complete
setting (`TFSetting`) saves to and loads from JSON, validated at the edge.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from chronocl.core.errors import InputNotFoundError, InvalidTransferFunctionError, UnknownNameError

TIME_COLORS = ("rgb", "warm-cool", "luminance", "white", "points")
TIME_ALPHAS = ("constant", "hat", "inverted-hat", "points")
TIME_POSITIONS = ("relative", "absolute")
MAX_JSON_BYTES = 16 * 2**20  # a transfer-function file larger than this is not one

# Colours of the presets at p = 0, 0.5, 1 (oldest, middle, newest), interpolated linearly.
_PRESET_STOPS = {
    "rgb": ((0.0, 0.0, 0.0, 1.0), (0.5, 0.0, 1.0, 0.0), (1.0, 1.0, 0.0, 0.0)),
    "warm-cool": ((0.0, 0.23, 0.42, 1.0), (0.5, 0.80, 0.80, 0.80), (1.0, 1.0, 0.35, 0.08)),
    "white": ((0.0, 1.0, 1.0, 1.0), (1.0, 1.0, 1.0, 1.0)),
}


def _bad(msg: str) -> InvalidTransferFunctionError:
    return InvalidTransferFunctionError(msg)


_JSON_TYPES = {str: "the string", list: "the list", tuple: "the list", dict: "the object"}


def _show(value: object, most: int = 60) -> str:
    """A value for a one-line message: its repr, shortened."""
    try:
        text = repr(value).replace("\n", " ")
    except RecursionError:
        return "(nested too deeply to show)"
    return text if len(text) <= most else text[: most - 3] + "..."


def _got(value: object) -> str:
    """What a JSON value is, for 'must be ..., got <this>'."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return f"the number {_show(value)}"
    return f"{_JSON_TYPES.get(type(value), type(value).__name__)} {_show(value)}"


def _number(value: object, what: str) -> float:
    """A finite number (int or float, not a string or true/false) as float."""
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise _bad(f"{what} must be a number, got {_got(value)}")
    try:
        x = float(value)
    except OverflowError:  # an int beyond float
        x = math.inf
    if not math.isfinite(x):
        raise _bad(f"{what} is {_show(value)}; every transfer-function value must be finite")
    return x


def _finite_unit(value: object, what: str) -> float:
    x = _number(value, what)
    if not 0.0 <= x <= 1.0:
        raise _bad(f"{what} is {x}, outside [0, 1]; transfer-function values lie in [0, 1]")
    return x


def _parse_points(points: object, n: int, what: str, names: str) -> tuple[tuple[float, ...], ...]:
    """Validate control points: each n numbers in [0, 1], strictly increasing first entries."""
    if isinstance(points, np.ndarray):
        points = points.tolist()
    if not isinstance(points, Sequence) or isinstance(points, str) or len(points) == 0:
        raise _bad(f"{what} needs a non-empty list of control points ({names})")
    out = []
    for i, pt in enumerate(points):
        if isinstance(pt, np.ndarray):
            pt = pt.tolist()
        if not isinstance(pt, Sequence) or isinstance(pt, str):
            raise _bad(f"{what} point {i} must be a list of {n} numbers ({names}), got {_got(pt)}")
        if len(pt) != n:
            raise _bad(f"{what} point {i} has {len(pt)} entries, expected {n} ({names})")
        out.append(tuple(_finite_unit(v, f"{what} point {i} entry {j}") for j, v in enumerate(pt)))
    for i in range(1, len(out)):
        if out[i][0] <= out[i - 1][0]:
            raise _bad(
                f"{what} points must be sorted by position without repeats: point {i} at "
                f"{out[i][0]} follows {out[i - 1][0]}"
            )
    return tuple(out)


def _interp_points(points: tuple[tuple[float, ...], ...], x: np.ndarray) -> np.ndarray:
    """Piecewise-linear evaluation, constant beyond the first and last point."""
    pts = np.asarray(points, dtype=np.float64)
    return np.stack([np.interp(x, pts[:, 0], pts[:, j]) for j in range(1, pts.shape[1])], axis=-1)


# --------------------------------------------------------------------------- data TF


DEFAULT_DATA_POINTS = (
    (0.0, 1.0, 1.0, 1.0, 0.0),
    (0.35, 1.0, 1.0, 1.0, 0.0),
    (0.6, 1.0, 1.0, 1.0, 0.5),
    (1.0, 1.0, 1.0, 1.0, 0.9),
)


@dataclass(frozen=True)
class DataTF:
    """Piecewise-linear RGBA over the normalised value u, sampled into a LUT of `size` entries.

    `value_range` overrides the series' global (vmin, vmax) used to normalise values.
    The default colours by time: data colour white, opacity rising with the value.
    """

    points: tuple[tuple[float, ...], ...] = DEFAULT_DATA_POINTS
    size: int = 256
    value_range: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "points", _parse_points(self.points, 5, "data_tf", "u, r, g, b, a")
        )
        if isinstance(self.size, bool) or not isinstance(self.size, int | np.integer):
            raise _bad(f"data_tf size must be an integer, got {_got(self.size)}")
        if not 256 <= self.size <= 65536:
            raise _bad(f"data_tf size is {self.size}; use a LUT of 256 to 65536 entries")
        object.__setattr__(self, "size", int(self.size))
        if self.value_range is not None:
            object.__setattr__(self, "value_range", _value_range(self.value_range))

    @property
    def lut(self) -> np.ndarray:
        """RGBA float32 (size, 4), entry i at u = i / (size - 1)."""
        return _interp_points(self.points, np.linspace(0.0, 1.0, self.size)).astype(np.float32)

    def to_dict(self) -> dict:
        d: dict = {"points": [list(p) for p in self.points], "size": self.size}
        if self.value_range is not None:
            d["value_range"] = list(self.value_range)
        return d

    @classmethod
    def from_dict(cls, d: object) -> DataTF:
        _check_keys(d, "data_tf", {"points", "size", "value_range"})
        assert isinstance(d, dict)
        return cls(
            points=d.get("points", DEFAULT_DATA_POINTS),
            size=d.get("size", 256),
            value_range=d.get("value_range"),
        )


def _value_range(vr: object) -> tuple[float, float]:
    """[min, max]: two finite numbers within float32 (the engines' precision), min < max."""
    if isinstance(vr, np.ndarray):
        vr = vr.tolist()
    if not isinstance(vr, list | tuple) or len(vr) != 2:
        raise _bad(
            f"data_tf value_range must be a list of two numbers [min, max], got {_got(vr)}; "
            "e.g. [0, 1]"
        )
    lo, hi = (_number(v, "data_tf value_range") for v in vr)
    big = float(np.finfo(np.float32).max)
    if max(abs(lo), abs(hi)) > big:
        raise _bad(
            f"data_tf value_range {[lo, hi]} lies outside float32 (|v| <= {big:.3g}); "
            "give the data's range"
        )
    if not np.float32(lo) < np.float32(hi) or not math.isfinite(float(np.float32(hi) - lo)):
        raise _bad(
            f"data_tf value_range {[lo, hi]} must have min < max (distinct in float32); e.g. [0, 1]"
        )
    return lo, hi


def lut_lookup(lut: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Evaluate a LUT at u in [0, 1] with linear interpolation between entries: (..., 4)."""
    n = lut.shape[0]
    x = np.clip(u, 0.0, 1.0) * (n - 1)
    i0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    f = (x - i0)[..., None]
    lut64 = lut.astype(np.float64)
    return lut64[i0] * (1.0 - f) + lut64[i0 + 1] * f


def lut_lerp32(lut: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The LUT at u in float32, operation for operation as the OpenCL kernels do it:
    x = u * (N - 1); i0 = min(trunc(x), N - 2); f = x - i0; lut[i0] * (1 - f) + lut[i0 + 1] * f.
    Decisions on opacity (first_hit's threshold) then agree exactly between engines."""
    lut32 = np.asarray(lut, dtype=np.float32)
    n = lut32.shape[0]
    x = np.asarray(u, dtype=np.float32) * np.float32(n - 1)
    i0 = np.minimum(x.astype(np.int32), n - 2)
    f = (x - i0.astype(np.float32))[..., None]
    return lut32[i0] * (np.float32(1.0) - f) + lut32[i0 + 1] * f


# --------------------------------------------------------------------------- time TF


@dataclass(frozen=True)
class TimeColor:
    """Colour over time position p in [0, 1].

    Presets: ``rgb`` (oldest blue -> green -> newest red), ``warm-cool`` (cool blue
    -> grey -> warm orange), ``luminance`` (white at `focus`, fading linearly to black
    over a distance `falloff` in p), ``white``, and ``points`` ((p, r, g, b), ...).
    """

    preset: str = "rgb"
    focus: float = 1.0
    falloff: float = 1.0
    points: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.preset not in TIME_COLORS:
            raise UnknownNameError(
                f"unknown time colour preset {_show(self.preset)}; "
                f"choose one of {', '.join(TIME_COLORS)}"
            )
        _finite_unit(self.focus, "time colour focus")
        if _number(self.falloff, "time colour falloff") <= 0:
            raise _bad(f"time colour falloff is {self.falloff}; it must be a number > 0")
        if self.preset == "points":
            object.__setattr__(
                self, "points", _parse_points(self.points, 4, "time colour", "p, r, g, b")
            )

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        if self.preset == "luminance":
            lum = np.clip(1.0 - np.abs(p - self.focus) / self.falloff, 0.0, 1.0)
            return np.repeat(lum[..., None], 3, axis=-1)
        stops = self.points if self.preset == "points" else _PRESET_STOPS[self.preset]
        return _interp_points(stops, p)

    def to_dict(self) -> dict:
        d: dict = {"preset": self.preset}
        if self.preset == "luminance":
            d.update(focus=self.focus, falloff=self.falloff)
        if self.preset == "points":
            d["points"] = [list(q) for q in self.points]
        return d


@dataclass(frozen=True)
class TimeAlpha:
    """Opacity over time position p in [0, 1].

    ``constant`` (`value` everywhere); ``hat``: `value` at `center` falling linearly to
    `floor` at center ± width/2; ``inverted-hat``: `floor` at `center` rising to `value`
    at center ± width/2; ``points`` ((p, a), ...).
    """

    shape: str = "constant"
    value: float = 1.0
    center: float = 0.5
    width: float = 0.5
    floor: float = 0.0
    points: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.shape not in TIME_ALPHAS:
            raise UnknownNameError(
                f"unknown time alpha shape {_show(self.shape)}; "
                f"choose one of {', '.join(TIME_ALPHAS)}"
            )
        for name in ("value", "center", "floor"):
            _finite_unit(getattr(self, name), f"time alpha {name}")
        w = _number(self.width, "time alpha width")
        if not 0 < w <= 2:
            raise _bad(f"time alpha width is {self.width}; it must lie in (0, 2]")
        if self.shape == "points":
            object.__setattr__(self, "points", _parse_points(self.points, 2, "time alpha", "p, a"))

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        if self.shape == "constant":
            return np.full(p.shape, self.value)
        if self.shape == "points":
            return _interp_points(self.points, p)[..., 0]
        bump = np.clip(1.0 - np.abs(p - self.center) / (self.width / 2.0), 0.0, 1.0)
        if self.shape == "inverted-hat":
            bump = 1.0 - bump
        return self.floor + (self.value - self.floor) * bump

    def to_dict(self) -> dict:
        d: dict = {"shape": self.shape, "value": self.value}
        if self.shape in ("hat", "inverted-hat"):
            d.update(center=self.center, width=self.width, floor=self.floor)
        if self.shape == "points":
            d["points"] = [list(q) for q in self.points]
        return d


@dataclass(frozen=True)
class TimeTF:
    """Time transfer function: colour and opacity over time position, and how positions are made.

    ``relative``: p_k = k / (W - 1) (the paper's; p = 0 for W = 1). ``absolute``:
    p_k = s_k / (T - 1), so a step keeps its colour while the window slides.
    """

    color: TimeColor = field(default_factory=TimeColor)
    alpha: TimeAlpha = field(default_factory=TimeAlpha)
    positions: str = "relative"

    def __post_init__(self) -> None:
        if self.positions not in TIME_POSITIONS:
            raise UnknownNameError(
                f"unknown time positions {_show(self.positions)}; choose relative or absolute"
            )

    @classmethod
    def preset(cls, name: str, positions: str = "relative", **params: float) -> TimeTF:
        """A named preset: colours rgb, warm-cool, luminance, white; alphas hat, inverted-hat."""
        if name in ("hat", "inverted-hat"):
            return cls(color=TimeColor("rgb"), alpha=TimeAlpha(name, **params), positions=positions)
        if name in ("rgb", "warm-cool", "luminance", "white"):
            return cls(color=TimeColor(name, **params), positions=positions)
        if name == "constant":
            return cls(alpha=TimeAlpha("constant", **params), positions=positions)
        raise UnknownNameError(
            f"unknown time TF preset {name!r}; choose one of "
            "rgb, warm-cool, luminance, white, hat, inverted-hat, constant"
        )

    def positions_of(self, steps: Sequence[int], n_steps: int) -> np.ndarray:
        """Time positions p_k in [0, 1] of the selected steps."""
        s = np.asarray(steps, dtype=np.float64)
        if self.positions == "absolute":
            return s / (n_steps - 1) if n_steps > 1 else np.zeros_like(s)
        w = len(s)
        return np.arange(w, dtype=np.float64) / (w - 1) if w > 1 else np.zeros(w)

    def evaluate(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rgb_t (..., 3), a_t (...)) at positions p."""
        return self.color.evaluate(p), self.alpha.evaluate(p)

    def to_dict(self) -> dict:
        return {
            "color": self.color.to_dict(),
            "alpha": self.alpha.to_dict(),
            "positions": self.positions,
        }

    @classmethod
    def from_dict(cls, d: object) -> TimeTF:
        _check_keys(d, "time_tf", {"color", "alpha", "positions"})
        assert isinstance(d, dict)
        color = d.get("color", {"preset": "rgb"})
        alpha = d.get("alpha", {"shape": "constant"})
        _check_keys(color, "time_tf.color", {"preset", "focus", "falloff", "points"})
        _check_keys(
            alpha, "time_tf.alpha", {"shape", "value", "center", "width", "floor", "points"}
        )
        return cls(
            color=TimeColor(**color),
            alpha=TimeAlpha(**alpha),
            positions=d.get("positions", "relative"),
        )


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class TFSetting:
    """A complete transfer-function setting: data TF and time TF, saved as JSON."""

    data_tf: DataTF = field(default_factory=DataTF)
    time_tf: TimeTF = field(default_factory=TimeTF)

    def to_dict(self) -> dict:
        return {"data_tf": self.data_tf.to_dict(), "time_tf": self.time_tf.to_dict()}

    @classmethod
    def from_dict(cls, d: object) -> TFSetting:
        _check_keys(d, "transfer-function setting", {"data_tf", "time_tf"})
        assert isinstance(d, dict)
        return cls(
            data_tf=DataTF.from_dict(d.get("data_tf", {})),
            time_tf=TimeTF.from_dict(d.get("time_tf", {})),
        )

    def save(self, path: str | os.PathLike) -> None:
        from chronocl.core.atomic import atomic_file

        with atomic_file(path, overwrite=True) as tmp:
            tmp.write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike) -> TFSetting:
        from chronocl.core.paths import check_input

        p = check_input(path, "transfer-function file", want="file", hint="check the --tf path")
        if p.stat().st_size > MAX_JSON_BYTES:
            raise _bad(
                f"{p.name} has {p.stat().st_size} bytes; a transfer-function file is small "
                f"JSON (at most {MAX_JSON_BYTES // 2**20} MiB); check --tf"
            )
        try:
            d = json.loads(p.read_text(encoding="utf-8"), parse_constant=_reject_constant)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise _bad(f"{p.name} is not valid JSON ({exc}); fix the file") from None
        except RecursionError:
            raise _bad(
                f"{p.name} nests lists or objects too deeply to read; a transfer function "
                "needs three levels at most"
            ) from None
        except OSError as exc:
            raise InputNotFoundError(
                f"transfer-function file {str(p)!r} cannot be read ({exc.strerror or exc}); "
                "check its permissions"
            ) from None
        try:
            return cls.from_dict(d)
        except InvalidTransferFunctionError as exc:
            raise _bad(f"{p.name}: {exc}") from None
        except RecursionError:
            raise _bad(f"{p.name} nests lists too deeply; fix the file") from None


def _reject_constant(name: str) -> float:
    raise _bad(f"{name} is not allowed in a transfer function; use finite numbers")


def _check_keys(d: object, what: str, allowed: set[str]) -> None:
    if not isinstance(d, dict):
        raise _bad(f"{what} must be a JSON object {{...}}, got {_got(d)}")
    unknown = sorted(set(d) - allowed)
    if unknown:
        raise _bad(f"{what} has unknown key {unknown[0]!r}; allowed: {', '.join(sorted(allowed))}")
