"""Known answers: hand-computed voxels for each mode and order (docs/semantics.md)."""

from __future__ import annotations

import numpy as np
import pytest

from chronocl import reference
from chronocl.core import values
from chronocl.core.enhance import Enhance
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TimeTF
from chronocl.modes.spec import IntegrationSpec, resolve_order

# a_d(u) = u, data colour white; time colour rgb (blue, green, red), time alpha 1.
LINEAR = DataTF(points=[(0, 1, 1, 1, 0), (1, 1, 1, 1, 1)])
SEL = Selection((2, 5, 9), 10)  # three steps; relative positions 0, 0.5, 1
# voxel 0: u = 0.5, 0.25, 1.0 over the steps; voxel 1: all zero.
U = np.array([[0.5, 0.0], [0.25, 0.0], [1.0, 0.0]], dtype=np.float32).reshape(3, 1, 1, 2)


def run(mode: str, order="forward", **kw):
    spec = IntegrationSpec(mode=mode, order=order, data_tf=LINEAR, time_tf=TimeTF(), **kw)
    pos = spec.time_tf.positions_of(SEL.steps, SEL.n_steps)
    rgba, t_index = reference.integrate(U, SEL.steps, pos, resolve_order(spec.order, SEL), spec)
    return rgba[0, 0], (None if t_index is None else t_index[0, 0])


@pytest.mark.parametrize(
    ("order", "expected"),
    [
        # blue 0.5 in front; green 0.25 through 0.5 transmittance; red fills the rest.
        ("forward", [0.375, 0.125, 0.5, 1.0]),
        # red (alpha 1) in front hides the rest.
        ("backward", [1.0, 0.0, 0.0, 1.0]),
        # green 0.25 in front, then red takes the remaining 0.75.
        ((5, 9, 2), [0.75, 0.25, 0.0, 1.0]),
    ],
)
def test_alpha(order, expected):
    rgba, _ = run("alpha", order)
    np.testing.assert_allclose(rgba[0], expected, atol=1e-6)
    np.testing.assert_allclose(rgba[1], 0, atol=0)


@pytest.mark.parametrize(
    ("order", "threshold", "expected", "step"),
    [
        ("forward", 0.3, [0, 0, 0.5, 0.5], 2),
        ("backward", 0.3, [1, 0, 0, 1], 9),
        ((5, 9, 2), 0.3, [1, 0, 0, 1], 9),  # green (0.25) is below the threshold
        ((5, 9, 2), 0.0, [0, 0.25, 0, 0.25], 5),
    ],
)
def test_first_hit(order, threshold, expected, step):
    rgba, t_index = run("first_hit", order, threshold=threshold)
    np.testing.assert_allclose(rgba[0], expected, atol=1e-6)
    assert t_index[0] == step
    np.testing.assert_array_equal(rgba[1], 0)
    assert t_index[1] == -1  # nothing passes the threshold


@pytest.mark.parametrize("order", ["forward", "backward", (9, 2, 5)])
def test_additive(order):
    rgba, t_index = run("additive", order)
    # Σ α·c = 0.5 blue + 0.25 green + 1.0 red; N = (1, 1, 1); A = max α = 1.
    np.testing.assert_allclose(rgba[0], [1.0, 0.25, 0.5, 1.0], atol=1e-6)
    assert t_index is None


def test_additive_max_normalisation_and_clamp():
    rgba, _ = run("additive", normalize="max")
    # largest channel value in the volume is 1.0 (red), so the values stay; clamp to A = 1.
    np.testing.assert_allclose(rgba[0], [1.0, 0.25, 0.5, 1.0], atol=1e-6)
    two = Selection((2, 9), 10)
    spec = IntegrationSpec(mode="additive", data_tf=LINEAR, normalize="max")
    u = U[[0, 1]]  # u = 0.5 (blue), 0.25 (red): sums (0.25, 0, 0.5), max channel 0.5
    pos = spec.time_tf.positions_of(two.steps, 10)
    out, _ = reference.integrate(u, two.steps, pos, resolve_order("forward", two), spec)
    # divided by 0.5 -> (0.5, 0, 1.0), then clamped to A = 0.5
    np.testing.assert_allclose(out[0, 0, 0], [0.5, 0.0, 0.5, 0.5], atol=1e-6)
    # normalise by N = (1, 0, 1): green has N = 0 -> 0
    spec_t = IntegrationSpec(mode="additive", data_tf=LINEAR, normalize="time")
    out, _ = reference.integrate(u, two.steps, pos, resolve_order("forward", two), spec_t)
    np.testing.assert_allclose(out[0, 0, 0], [0.25, 0.0, 0.5, 0.5], atol=1e-6)


@pytest.mark.parametrize(
    ("mode", "order", "expected", "step", "tie_step"),
    [
        ("max", "forward", [1, 0, 0, 1], 9, 2),  # u = 1.0 at step 9; zeros tie -> first
        ("max", "backward", [1, 0, 0, 1], 9, 9),
        ("min", "forward", [0, 0.25, 0, 0.25], 5, 2),
        ("min", (5, 9, 2), [0, 0.25, 0, 0.25], 5, 5),
    ],
)
def test_max_min(mode, order, expected, step, tie_step):
    rgba, t_index = run(mode, order)
    np.testing.assert_allclose(rgba[0], expected, atol=1e-6)
    assert t_index[0] == step
    assert t_index[1] == tie_step  # all-zero voxel: the tie goes to the first in order
    np.testing.assert_array_equal(rgba[1], 0)


def test_edge_and_silhouette_factors():
    u = np.array([0.0, 0.5, 1.0], dtype=np.float32).reshape(1, 1, 3)  # |g| = 0.5 along x
    from chronocl.core.enhance import factor

    np.testing.assert_allclose(factor(u, Enhance("edge", 0.1, 2.0, 2.0)), 0.1 + 2.0 * 0.25)
    along = factor(u, Enhance("silhouette", 0.2, 1.0, 1.0, view=(1, 0, 0)))
    across = factor(u, Enhance("silhouette", 0.2, 1.0, 1.0, view=(0, 1, 0)))
    np.testing.assert_allclose(along, 0.2)  # gradient faces the viewer: no silhouette
    np.testing.assert_allclose(across, 1.2)  # gradient across the view: full silhouette
    flat = np.zeros((2, 2, 2), dtype=np.float32)
    np.testing.assert_allclose(factor(flat, Enhance("silhouette", 0.3, 1.0, 1.0)), 0.3)


def test_enhancement_scales_alpha_and_clamps():
    u = np.array([0.0, 0.5, 1.0], dtype=np.float32).reshape(1, 1, 1, 3)
    sel = Selection((0,), 1)
    spec = IntegrationSpec(
        mode="alpha",
        data_tf=LINEAR,
        time_tf=TimeTF.preset("white"),
        enhance=Enhance("edge", 0, 3, 1),
    )
    rgba, _ = reference.integrate(u, sel.steps, np.zeros(1), np.arange(1), spec)
    # e = 3 * 0.5 = 1.5: alpha = clip(u * 1.5, 0, 1)
    np.testing.assert_allclose(rgba[0, 0, :, 3], [0.0, 0.75, 1.0], atol=1e-6)
    np.testing.assert_allclose(rgba[0, 0, :, 0], [0.0, 0.75, 1.0], atol=1e-6)


def test_normalize_values():
    v = np.array([-1.0, 0.0, 5.0, 10.0, 11.0])
    np.testing.assert_allclose(values.normalize(v, 0.0, 10.0), [0, 0, 0.5, 1, 1])
    np.testing.assert_array_equal(values.normalize(v, 3.0, 3.0), 0)


@pytest.mark.parametrize("engine", ["numpy", "opencl"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize(("order", "step"), [("forward", 1), ("backward", 3), ((2, 0, 1, 3), 2)])
def test_change_ties_equal_changes_exactly(engine, dtype, order, step):
    """Equal changes of the stored values tie whatever rounding u would have: steps 0, 7, 14,
    21 change by 7 each time, so the first in the order wins; δ = 7 / 255."""
    import chronocl

    raw = np.zeros((4, 1, 1, 37), dtype=np.float32)
    raw[:, 0, 0, :] = np.array([0, 7, 14, 21], dtype=np.float32)[:, None]
    raw[0, 0, 0, 1], raw[1, 0, 0, 1] = 255, 255  # the range is 0..255; voxel 1 changes once
    series = chronocl.TimeSeries.from_array(raw.astype(dtype))
    spec = IntegrationSpec(mode="change", order=order, data_tf=LINEAR)
    cv = chronocl.integrate(series, spec=spec, engine=engine)
    t = cv.t_index[0, 0]
    assert t[0] == step and np.all(t[2:] == step)
    assert t[1] == 2  # 255 -> 14 is the largest change there
    # a_d(δ) = δ: the opacity of the winner is the change in u
    np.testing.assert_allclose(cv.rgba[0, 0, 0, 3], 7 / 255, rtol=1e-6)
