"""Hypothesis strategies: random windows, transfer functions and integration specs."""

from __future__ import annotations

import os

import numpy as np
from hypothesis import strategies as st

from chronocl import modes
from chronocl.core.enhance import Enhance
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TimeAlpha, TimeColor, TimeTF
from chronocl.modes.spec import IntegrationSpec


def examples(n: int) -> int:
    """A property test's number of examples: `n`, sized for CI's time, or CHRONOCL_EXAMPLES when
    that is set (every property test then draws that many: a deeper search)."""
    deeper = os.environ.get("CHRONOCL_EXAMPLES")
    return int(deeper) if deeper else n


shapes = st.tuples(st.integers(1, 7), st.integers(1, 6), st.integers(1, 6))
# x spans 1..40 so the OpenCL engine's 16-voxel lanes and its scalar x tail are both exercised.
wide_shapes = st.tuples(st.integers(1, 4), st.integers(1, 3), st.integers(1, 40))


# Factors of opacity (TF opacities, enhancement weights) are 0 or far above float32's smallest
# normal numbers, even multiplied together: 1e-300 times an opacity is 0 in the float32
# arithmetic the engines share but not in the float64 these tests check with.
def opacity_factors(high: float = 1.0):
    return st.one_of(st.just(0.0), st.floats(1e-12, high))


@st.composite
def data_tfs(draw) -> DataTF:
    n = draw(st.integers(2, 5))
    us = sorted(set(draw(st.lists(st.floats(0, 1), min_size=n, max_size=n))))
    if len(us) < 2:
        us = [0.0, 1.0]
    unit = st.floats(0, 1)
    opacity = opacity_factors()
    if draw(st.booleans()):  # constant colour: the engine's colour-by-time fast path
        rgb = (draw(unit), draw(unit), draw(unit))
        points = [(u, *rgb, draw(opacity)) for u in us]
    else:
        points = [(u, draw(unit), draw(unit), draw(unit), draw(opacity)) for u in us]
    return DataTF(points=points, size=draw(st.sampled_from([256, 300, 1024])))


@st.composite
def time_tfs(draw, positions=None) -> TimeTF:
    color = draw(
        st.sampled_from(
            [
                TimeColor("rgb"),
                TimeColor("warm-cool"),
                TimeColor("luminance", focus=draw(st.floats(0, 1)), falloff=0.7),
                TimeColor("white"),
            ]
        )
    )
    alpha = draw(
        st.sampled_from(
            [
                TimeAlpha("constant", value=draw(st.floats(0.05, 1))),
                TimeAlpha("hat", center=draw(st.floats(0, 1)), width=0.8, floor=0.1),
                TimeAlpha("inverted-hat", center=draw(st.floats(0, 1)), width=0.6, floor=0.2),
            ]
        )
    )
    pos = positions or draw(st.sampled_from(["relative", "absolute"]))
    return TimeTF(color=color, alpha=alpha, positions=pos)


enhancements = st.one_of(
    st.just(Enhance()),
    st.builds(Enhance, st.just("edge"), opacity_factors(), opacity_factors(8), st.floats(0.5, 2)),
    st.builds(
        Enhance,
        st.just("silhouette"),
        opacity_factors(),
        opacity_factors(),
        st.floats(0.5, 2),
        st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.1, 1)),
    ),
)


@st.composite
def windows(draw, max_w: int = 9, wide: bool = False):
    """(u (W, Z, Y, X) float32, Selection) with W random and steps spread over T."""
    shape = draw(wide_shapes if wide else shapes)
    w = draw(st.integers(1, max_w))
    n_steps = draw(st.integers(w, w + 6))
    steps = sorted(draw(st.permutations(range(n_steps)))[:w])
    seed = draw(st.integers(0, 2**31))
    rng = np.random.default_rng(seed)
    u = rng.random((w, *shape), dtype=np.float32)
    # Coarse levels make exact ties, so thresholds and argmax tie-breaking are exercised.
    if draw(st.booleans()):
        u = (np.round(u * 4) / 4).astype(np.float32)
    return u, Selection(tuple(steps), n_steps)


@st.composite
def specs(draw, mode=None, selection: Selection | None = None, positions=None) -> IntegrationSpec:
    mode = mode or draw(st.sampled_from(modes.names()))
    if selection is not None and draw(st.booleans()):
        order = tuple(draw(st.permutations(selection.steps)))
    else:
        order = draw(st.sampled_from(["forward", "backward"]))
    return IntegrationSpec(
        mode=mode,
        order=order,
        data_tf=draw(data_tfs()),
        time_tf=draw(time_tfs(positions)),
        enhance=draw(enhancements),
        threshold=draw(st.sampled_from([0.0, 0.1, 0.5])),
        normalize=draw(st.sampled_from(["time", "max"])),
    )
