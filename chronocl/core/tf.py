"""Transfer functions: the data TF (value -> RGBA), LUTs, and complete settings saved as JSON.

A voxel's value u in [0, 1] at step k with time position p_k gets
colour c_k = rgb_d(u) * rgb_t(p_k) and opacity α_k = a_d(u) * a_t(p_k) * e_k
(docs/semantics.md). The data TF is piecewise linear over control points and
is sampled into a LUT that is evaluated with linear interpolation between
entries; the engines all use that LUT, so they agree to rounding. A complete
setting (`TFSetting`) saves to and loads from JSON, validated at the edge. The time TF is in
`chronocl.core.time_tf` and handed on from here.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, replace

import numpy as np

from chronocl.core.colormaps import apply_colormap
from chronocl.core.errors import InputNotFoundError, InvalidTransferFunctionError
from chronocl.core.tf_input import (
    bad,
    check_keys,
    got,
    interp_points,
    number,
    parse_points,
    reject_constant,
)
from chronocl.core.time_tf import (
    TIME_ALPHAS,
    TIME_COLORS,
    TIME_POSITIONS,
    TimeAlpha,
    TimeColor,
    TimeTF,
)

__all__ = [
    "DEFAULT_DATA_POINTS",
    "MAX_JSON_BYTES",
    "TIME_ALPHAS",
    "TIME_COLORS",
    "TIME_POSITIONS",
    "DataTF",
    "TFSetting",
    "TimeAlpha",
    "TimeColor",
    "TimeTF",
    "lut_lerp32",
    "lut_lookup",
]

MAX_JSON_BYTES = 16 * 2**20  # a transfer-function file larger than this is not one


# --------------------------------------------------------------------------- data TF


# Transparent at the bottom of the range (by default the window's background), rising from
# just above it, so the faint parts of a window show beside its peaks.
DEFAULT_DATA_POINTS = (
    (0.0, 1.0, 1.0, 1.0, 0.0),
    (0.05, 1.0, 1.0, 1.0, 0.0),
    (0.3, 1.0, 1.0, 1.0, 0.25),
    (1.0, 1.0, 1.0, 1.0, 0.9),
)
# value_range: fitted to the selected window, or the series' range recorded at ingest.
FITTED, GLOBAL = "window", "global"


@dataclass(frozen=True)
class DataTF:
    """Piecewise-linear RGBA over the normalised value u, sampled into a LUT of `size` entries.

    `value_range` is what normalises values to u: ``"window"`` fits it to the selected
    window's own values per mode (`chronocl.integration.fit_range`), ``"global"`` takes the
    series' range recorded at ingest, (min, max) gives it. ``None`` (the default) means
    ``"window"`` for a TF with the default opacity curve (whatever its colours, e.g. a colour
    map) and ``"global"`` for one whose opacity was drawn by hand, against the series' range.
    The default colours by time: data colour white, opacity rising with the value.
    """

    points: tuple[tuple[float, ...], ...] = DEFAULT_DATA_POINTS
    size: int = 256
    value_range: tuple[float, float] | str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", parse_points(self.points, 5, "data_tf", "u, r, g, b, a"))
        if isinstance(self.size, bool) or not isinstance(self.size, int | np.integer):
            raise bad(f"data_tf size must be an integer, got {got(self.size)}")
        if not 256 <= self.size <= 65536:
            raise bad(f"data_tf size is {self.size}; use a LUT of 256 to 65536 entries")
        object.__setattr__(self, "size", int(self.size))
        if self.value_range is not None and self.value_range not in (FITTED, GLOBAL):
            object.__setattr__(self, "value_range", _value_range(self.value_range))

    @property
    def range_kind(self) -> str:
        """What normalises values: "window" (fitted), "global" or "given"."""
        vr = self.value_range
        if isinstance(vr, tuple):
            return "given"
        if vr is None:
            u = np.linspace(0.0, 1.0, 257)
            mine = interp_points(self.points, u)[:, 3]
            default = interp_points(DEFAULT_DATA_POINTS, u)[:, 3]
            return FITTED if np.allclose(mine, default, rtol=0, atol=1e-9) else GLOBAL
        return vr

    @property
    def lut(self) -> np.ndarray:
        """RGBA float32 (size, 4), entry i at u = i / (size - 1)."""
        return interp_points(self.points, np.linspace(0.0, 1.0, self.size)).astype(np.float32)

    def with_colormap(self, name: str) -> DataTF:
        """This TF coloured by matplotlib's map `name` (e.g. "viridis", "magma", "grey",
        "coolwarm"), its opacity curve unchanged (`chronocl.core.colormaps`)."""
        return replace(self, points=apply_colormap(self.points, name))

    def to_dict(self) -> dict:
        d: dict = {"points": [list(p) for p in self.points], "size": self.size}
        if self.value_range is not None:
            vr = self.value_range
            d["value_range"] = vr if isinstance(vr, str) else list(vr)
        return d

    @classmethod
    def from_dict(cls, d: object) -> DataTF:
        check_keys(d, "data_tf", {"points", "size", "value_range"})
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
        raise bad(
            f"data_tf value_range must be a list of two numbers [min, max], "
            f'"{FITTED}" or "{GLOBAL}", got {got(vr)}; e.g. [0, 1]'
        )
    lo, hi = (number(v, "data_tf value_range") for v in vr)
    big = float(np.finfo(np.float32).max)
    if max(abs(lo), abs(hi)) > big:
        raise bad(
            f"data_tf value_range {[lo, hi]} lies outside float32 (|v| <= {big:.3g}); "
            "give the data's range"
        )
    if not np.float32(lo) < np.float32(hi) or not math.isfinite(float(np.float32(hi) - lo)):
        raise bad(
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


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class TFSetting:
    """A transfer-function setting: data TF and time TF, saved as JSON.

    `time_tf` None (a file without one) leaves the time TF unchosen: integration then takes
    `TimeTF.for_data(data_tf.points)`, time as hue for a grey data TF and as lightness for a
    coloured one (docs/semantics.md)."""

    data_tf: DataTF = field(default_factory=DataTF)
    time_tf: TimeTF | None = None

    def to_dict(self) -> dict:
        d: dict = {"data_tf": self.data_tf.to_dict()}
        if self.time_tf is not None:
            d["time_tf"] = self.time_tf.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: object) -> TFSetting:
        check_keys(d, "transfer-function setting", {"data_tf", "time_tf"})
        assert isinstance(d, dict)
        return cls(
            data_tf=DataTF.from_dict(d.get("data_tf", {})),
            time_tf=TimeTF.from_dict(d["time_tf"]) if "time_tf" in d else None,
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
            raise bad(
                f"{p.name} has {p.stat().st_size} bytes; a transfer-function file is small "
                f"JSON (at most {MAX_JSON_BYTES // 2**20} MiB); check --tf"
            )
        try:
            d = json.loads(p.read_text(encoding="utf-8"), parse_constant=reject_constant)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise bad(f"{p.name} is not valid JSON ({exc}); fix the file") from None
        except RecursionError:
            raise bad(
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
            raise bad(f"{p.name}: {exc}") from None
        except RecursionError:
            raise bad(f"{p.name} nests lists too deeply; fix the file") from None
