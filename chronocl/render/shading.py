"""Gradient shading of a chronovolume: Blinn-Phong lighting with a headlight.

The normal at a sample is the negated gradient of the chronovolume's opacity (central
differences in the raycaster, kernels/glsl/raycast.frag), the light comes from the camera, so
what faces the viewer is brightest. A sample's colour becomes
colour * (ambient + diffuse * |n.l|) + specular * |n.h|^shininess * opacity (premultiplied),
before it is composited; where the opacity barely changes (inside a uniform region) it keeps
its flat colour. Off unless asked for: with shading off the raycaster runs today's shader.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from chronocl.core.errors import InvalidParameterError

COEFFICIENTS = ("ambient", "diffuse", "specular")
MAX_COEFFICIENT = 2.0
MIN_SHININESS, MAX_SHININESS = 1.0, 256.0


def _finite(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class Shading:
    """Lighting of a render: `Shading()` is on with defaults, `Shading(enabled=False)` off."""

    enabled: bool = True
    ambient: float = 0.3
    diffuse: float = 0.7
    specular: float = 0.3
    shininess: float = 24.0

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise InvalidParameterError(f"shading enabled is {self.enabled!r}; give true or false")
        for name in COEFFICIENTS:
            value = getattr(self, name)
            if not _finite(value) or not 0.0 <= value <= MAX_COEFFICIENT:
                raise InvalidParameterError(
                    f"shading {name} is {value!r}; use a number from 0 to {MAX_COEFFICIENT:g}, "
                    f"e.g. ambient 0.3, diffuse 0.7, specular 0.3"
                )
        if not _finite(self.shininess) or not (MIN_SHININESS <= self.shininess <= MAX_SHININESS):
            raise InvalidParameterError(
                f"shading shininess is {self.shininess!r}; use {MIN_SHININESS:g} to "
                f"{MAX_SHININESS:g} (larger: smaller, sharper highlights)"
            )

    @classmethod
    def parse(cls, text: str) -> Shading:
        """'ambient,diffuse,specular[,shininess]', e.g. '0.3,0.7,0.3' or '0.2,0.8,0.5,40'."""
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            values = []
        if len(values) not in (3, 4):
            raise InvalidParameterError(
                f"shading parameters {text!r} must be ambient,diffuse,specular[,shininess], "
                "e.g. 0.3,0.7,0.3"
            )
        return cls(True, *values)

    @classmethod
    def from_dict(cls, data: object) -> Shading:
        """From `to_dict`'s form (the viewer's `shading` field); missing keys take defaults."""
        if not isinstance(data, dict):
            raise InvalidParameterError(
                f"shading {data!r} must be an object such as "
                '{"enabled": true, "ambient": 0.3, "diffuse": 0.7, "specular": 0.3}'
            )
        unknown = set(data) - set(cls.__dataclass_fields__)
        if unknown:
            raise InvalidParameterError(
                f"shading has unknown field(s) {', '.join(sorted(map(str, unknown)))}; use "
                "enabled, ambient, diffuse, specular, shininess"
            )
        return cls(**data)

    def to_dict(self) -> dict:
        return asdict(self)


OFF = Shading(enabled=False)


def as_shading(value: object) -> Shading:
    """A Shading from None/False (off), True (defaults), a Shading or its dict form."""
    if value is None or value is False:
        return OFF
    if value is True:
        return Shading()
    if isinstance(value, Shading):
        return value
    if isinstance(value, dict):
        return Shading.from_dict(value)
    raise InvalidParameterError(
        f"shading {value!r}: give True, False, a chronocl.render.Shading or a dict of its fields"
    )
