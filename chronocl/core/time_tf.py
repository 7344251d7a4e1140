"""The time transfer function: time position p -> (rgb_t, a_t), its presets and shapes.

Time positions are ``relative`` (k / (W - 1), the paper's) or ``absolute`` (s_k / (T - 1), so
a step keeps its colour while a window slides); see docs/semantics.md.

Colour is c_k = rgb_d(u) * rgb_t(p_k), so a data TF with hue (a colour map) times hued time
colours multiplies into dark mud. Where the time colours are not chosen they follow the data
TF (`TimeTF.for_data`): hue tells time (``rgb``) while the data TF is grey or white, and
lightness tells time (``lightness``, a grey ramp) once the data TF has hue, so each encoding
keeps a channel of its own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from chronocl.core.colormaps import has_hue
from chronocl.core.errors import UnknownNameError
from chronocl.core.tf_input import (
    bad,
    check_keys,
    finite_unit,
    interp_points,
    number,
    parse_points,
    show,
)

TIME_COLORS = ("rgb", "warm-cool", "lightness", "luminance", "white", "points")
TIME_ALPHAS = ("constant", "hat", "inverted-hat", "points")
TIME_POSITIONS = ("relative", "absolute")

# The grey of the oldest step under ``lightness``: dark enough to read as old, light enough
# that a colour map's hue still shows (at 0.35 viridis' darkest purple is still purple).
LIGHTNESS_FLOOR = 0.35

# Colours of the presets at p = 0, 0.5, 1 (oldest, middle, newest), interpolated linearly.
_PRESET_STOPS = {
    "rgb": ((0.0, 0.0, 0.0, 1.0), (0.5, 0.0, 1.0, 0.0), (1.0, 1.0, 0.0, 0.0)),
    "warm-cool": ((0.0, 0.23, 0.42, 1.0), (0.5, 0.80, 0.80, 0.80), (1.0, 1.0, 0.35, 0.08)),
    "lightness": ((0.0, LIGHTNESS_FLOOR, LIGHTNESS_FLOOR, LIGHTNESS_FLOOR), (1.0, 1.0, 1.0, 1.0)),
    "white": ((0.0, 1.0, 1.0, 1.0), (1.0, 1.0, 1.0, 1.0)),
}


@dataclass(frozen=True)
class TimeColor:
    """Colour over time position p in [0, 1].

    Presets: ``rgb`` (oldest blue -> green -> newest red), ``warm-cool`` (cool blue
    -> grey -> warm orange), ``lightness`` (grey LIGHTNESS_FLOOR oldest -> white newest: time
    as lightness under a colour map's hue), ``luminance`` (white at `focus`, fading linearly
    to black over a distance `falloff` in p), ``white``, and ``points`` ((p, r, g, b), ...).
    """

    preset: str = "rgb"
    focus: float = 1.0
    falloff: float = 1.0
    points: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        if self.preset not in TIME_COLORS:
            raise UnknownNameError(
                f"unknown time colour preset {show(self.preset)}; "
                f"choose one of {', '.join(TIME_COLORS)}"
            )
        finite_unit(self.focus, "time colour focus")
        if number(self.falloff, "time colour falloff") <= 0:
            raise bad(f"time colour falloff is {self.falloff}; it must be a number > 0")
        if self.preset == "points":
            object.__setattr__(
                self, "points", parse_points(self.points, 4, "time colour", "p, r, g, b")
            )
        else:  # unused: dropped, so equal colours compare (and hash) equal
            object.__setattr__(self, "points", ())

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        if self.preset == "luminance":
            lum = np.clip(1.0 - np.abs(p - self.focus) / self.falloff, 0.0, 1.0)
            return np.repeat(lum[..., None], 3, axis=-1)
        stops = self.points if self.preset == "points" else _PRESET_STOPS[self.preset]
        return interp_points(stops, p)

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
                f"unknown time alpha shape {show(self.shape)}; "
                f"choose one of {', '.join(TIME_ALPHAS)}"
            )
        for name in ("value", "center", "floor"):
            finite_unit(getattr(self, name), f"time alpha {name}")
        w = number(self.width, "time alpha width")
        if not 0 < w <= 2:
            raise bad(f"time alpha width is {self.width}; it must lie in (0, 2]")
        if self.shape == "points":
            object.__setattr__(self, "points", parse_points(self.points, 2, "time alpha", "p, a"))
        else:  # unused: dropped, so equal opacities compare (and hash) equal
            object.__setattr__(self, "points", ())

    def evaluate(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        if self.shape == "constant":
            return np.full(p.shape, self.value)
        if self.shape == "points":
            return interp_points(self.points, p)[..., 0]
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
                f"unknown time positions {show(self.positions)}; choose relative or absolute"
            )

    @classmethod
    def preset(cls, name: str, positions: str = "relative", **params: float) -> TimeTF:
        """A named preset: colours rgb, warm-cool, lightness, luminance, white; alphas hat,
        inverted-hat."""
        if name in ("hat", "inverted-hat"):
            return cls(color=TimeColor("rgb"), alpha=TimeAlpha(name, **params), positions=positions)
        if name in ("rgb", "warm-cool", "lightness", "luminance", "white"):
            return cls(color=TimeColor(name, **params), positions=positions)
        if name == "constant":
            return cls(alpha=TimeAlpha("constant", **params), positions=positions)
        raise UnknownNameError(
            f"unknown time TF preset {name!r}; choose one of "
            "rgb, warm-cool, lightness, luminance, white, hat, inverted-hat, constant"
        )

    @classmethod
    def for_data(cls, data_points: Sequence[Sequence[float]]) -> TimeTF:
        """The time TF where none is chosen, for a data TF with control points (u, r, g, b, a):
        ``rgb`` colours (time as hue) while the data TF is grey or white, ``lightness`` (time
        as lightness) once it has hue, e.g. a colour map; constant opacity 1, relative."""
        return cls(color=TimeColor("lightness" if has_hue(data_points) else "rgb"))

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
        check_keys(d, "time_tf", {"color", "alpha", "positions"})
        assert isinstance(d, dict)
        color = d.get("color", {"preset": "rgb"})
        alpha = d.get("alpha", {"shape": "constant"})
        check_keys(color, "time_tf.color", {"preset", "focus", "falloff", "points"})
        check_keys(alpha, "time_tf.alpha", {"shape", "value", "center", "width", "floor", "points"})
        return cls(
            color=TimeColor(**color),
            alpha=TimeAlpha(**alpha),
            positions=d.get("positions", "relative"),
        )
