"""Colour maps for the data transfer function: matplotlib's maps, entered as evenly spaced stops.

The data TF is piecewise linear, so a colour map enters it as `STOPS` evenly spaced points
coloured as the map is there (33 stops stay within about 5/255 of each preset, 2 % of the
range, which a rendering does not show). Applying a map keeps the opacity curve exactly: every new
point takes the curve's opacity at its position, and the existing points keep theirs. The
viewer gets the same stops in its `info` message, so a preset chosen in the page and
`--colormap` on the command line give the same transfer function.

The presets' stops are a table, `colormap_presets.json`, so that a viewer's or widget's first
message does not wait for matplotlib's import (0.06-0.3 s on 2 cores); other names ask
matplotlib. tests/test_tf.py checks the table against matplotlib; `write_presets()` writes it
again.

`has_hue` and `is_white` classify a data TF's colours: one with hue makes the time colours
default to lightness (`chronocl.core.time_tf.TimeTF.for_data`), and any but plain white gets a
data colour bar beside the time legend (`chronocl.render.colorbar`).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidTransferFunctionError

# The maps the viewer's menu offers; any other matplotlib map name works everywhere too.
PRESETS = ("viridis", "magma", "inferno", "cividis", "grey", "coolwarm", "RdBu_r", "turbo")
STOPS = 33
_ALIASES = {"grey": "gray", "gray_r": "gray_r", "grey_r": "gray_r"}
# Channels further apart than this make a colour a hue rather than a grey (a map entered as
# stops, rounded to 6 decimals, keeps its greys exactly grey).
HUE_TOLERANCE = 0.02
_PRESET_TABLE = Path(__file__).with_name("colormap_presets.json")


def colormap_stops(name: str) -> list[list[float]]:
    """[u, r, g, b] at STOPS evenly spaced u in [0, 1] of matplotlib's map `name`."""
    if isinstance(name, str) and name in PRESETS:
        return [list(stop) for stop in _presets()[name]]
    from matplotlib import colormaps  # matplotlib costs ~0.3 s to import: only when used

    if not isinstance(name, str) or _ALIASES.get(name, name) not in colormaps:
        raise InvalidTransferFunctionError(
            f"unknown colour map {name!r}; use one of {', '.join(PRESETS)} "
            "or another matplotlib colour map name"
        )
    return [list(stop) for stop in matplotlib_stops(name)]


@functools.cache
def _presets() -> dict[str, list[list[float]]]:
    return json.loads(_PRESET_TABLE.read_text())


def write_presets() -> None:
    """Write the presets' table from matplotlib (after a change to PRESETS or STOPS)."""
    table = {name: [list(stop) for stop in matplotlib_stops(name)] for name in PRESETS}
    _PRESET_TABLE.write_text(json.dumps(table, separators=(",", ":")) + "\n")


@functools.cache
def matplotlib_stops(name: str) -> tuple[tuple[float, ...], ...]:
    """The stops of matplotlib's map `name` (a preset's, or any other it knows)."""
    from matplotlib import colormaps

    name = _ALIASES.get(name, name)
    u = np.linspace(0.0, 1.0, STOPS)
    rgb = colormaps[name](u)[:, :3]
    return tuple(
        (round(float(x), 6), *(round(float(c), 6) for c in row))
        for x, row in zip(u, rgb, strict=True)
    )


def apply_colormap(
    points: Sequence[Sequence[float]], name: str
) -> tuple[tuple[float, float, float, float, float], ...]:
    """Data TF points (u, r, g, b, a) recoloured with map `name`: the points at the map's stops
    and at the existing positions, each coloured by the map and with the opacity the existing
    curve has there (so the opacity curve is unchanged)."""
    stops = np.asarray(colormap_stops(name))
    pts = np.asarray(points, dtype=np.float64)
    u = np.union1d(pts[:, 0], stops[:, 0])
    u = u[np.concatenate([[True], np.diff(u) > 1e-9])]
    alpha = np.interp(u, pts[:, 0], pts[:, 4])
    rgb = [np.interp(u, stops[:, 0], stops[:, j]) for j in (1, 2, 3)]
    return tuple(
        (float(x), float(r), float(g), float(b), float(a))
        for x, r, g, b, a in zip(u, *rgb, alpha, strict=True)
    )


def has_hue(points: Sequence[Sequence[float]]) -> bool:
    """Whether some control point (u, r, g, b, ...) has a colour that is not a grey."""
    rgb = np.asarray(points, dtype=np.float64)[:, 1:4]
    return bool((np.ptp(rgb, axis=1) > HUE_TOLERANCE).any())


def is_white(points: Sequence[Sequence[float]]) -> bool:
    """Whether every control point (u, r, g, b, ...) is plain white: colour then tells time
    alone, and a data colour bar would say nothing."""
    rgb = np.asarray(points, dtype=np.float64)[:, 1:4]
    return bool((rgb >= 1.0 - 1e-6).all())
