"""The data colour bar: what colour each value gets from the data TF, in data units.

Colour is c_k = rgb_d(u) * rgb_t(p_k); the time legend explains rgb_t, the colour bar rgb_d.
A chronovolume gets one whenever its data TF's colours are not plain white (a colour map, or
any coloured TF): the bar shows rgb_d over the value range the integration actually used, the
one its metadata records (`value_range`: given, the series', or fitted to the window), so its
ticks name the values the picture shows. The saved PNG draws it beside the time legend
(`chronocl.render.legends`), the viewer beside its on-view legend (`chronocl.viewer.frames`).

A mode that looks the data TF up at a change (its `data_axis`) has its bar over that: `change`
looks it up at δ, a change in units of the value range, so its bar runs from 0 to the range's
width. `count` looks it up at the fraction of steps, which its own legend already shows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chronocl.core.colormaps import is_white
from chronocl.core.tf import lut_lookup


@dataclass(frozen=True)
class DataBar:
    """rgb_d of a data TF over [lo, hi] in data units, named `title` ("value" or "change")."""

    title: str
    lo: float
    hi: float
    lut: np.ndarray  # the data TF's RGBA LUT, over u in [0, 1]

    def rgb(self, n: int) -> np.ndarray:
        """(n, 3) colours at n evenly spaced values from lo to hi."""
        return lut_lookup(self.lut, np.linspace(0.0, 1.0, n))[:, :3]


def data_bar(cv) -> DataBar | None:
    """The colour bar of chronovolume `cv`, or None where its data TF is plain white (colour
    then tells time alone) or its mode shows the data TF over the fraction of steps."""
    from chronocl.modes.spec import IntegrationSpec

    spec = IntegrationSpec.from_dict(cv.metadata["spec"])
    mode = spec.integration
    if is_white(spec.data_tf.points) or mode.legend == "fraction":
        return None
    recorded = cv.metadata.get("value_range")
    if recorded is None:  # made elsewhere: the bar over u itself, named so
        return DataBar("u", 0.0, 1.0, spec.data_tf.lut)
    lo, hi = (float(v) for v in recorded)
    if mode.data_axis == "change":  # δ = |Δu|: a difference of values within the range
        return DataBar("change", 0.0, hi - lo, spec.data_tf.lut)
    return DataBar("value", lo, hi, spec.data_tf.lut)
