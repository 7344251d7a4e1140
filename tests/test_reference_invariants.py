"""Property tests of the invariants of docs/semantics.md (1, 2, 3 and 5) for the numpy reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from chronocl import modes, reference
from chronocl.core.enhance import factor
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TimeAlpha, TimeTF, lut_lookup
from chronocl.data.series import TimeSeries
from chronocl.integration.inmemory import integrate
from chronocl.modes.spec import IntegrationSpec, resolve_order

from .strategies import examples, specs, windows

# Drawn transfer functions and data are often transparent on purpose; the warnings saying so
# (chronocl.integration.visibility) are tested in test_visibility.py.
pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


def ref(u, sel: Selection, spec: IntegrationSpec):
    pos = spec.time_tf.positions_of(sel.steps, sel.n_steps)
    return reference.integrate(u, sel.steps, pos, resolve_order(spec.order, sel), spec)


@pytest.mark.parametrize("mode", modes.names())
@settings(max_examples=examples(40))
@given(data=st.data())
def test_single_step_is_the_transfer_function(mode, data):
    """Invariant 1: W = 1 gives TF(u, p) premultiplied (additive: colour / N; count: the data
    TF at 0 or 1; change: nothing, no step changed)."""
    u, sel = data.draw(windows(max_w=1))
    spec = data.draw(specs(mode=mode, selection=sel))
    rgba, t_index = ref(u, sel, spec)

    p = spec.time_tf.positions_of(sel.steps, sel.n_steps)
    rgb_t, a_t = spec.time_tf.evaluate(p)
    d = lut_lookup(spec.data_tf.lut, u[0])
    alpha = np.clip(d[..., 3] * a_t[0] * factor(u[0], spec.enhance), 0, 1)
    colour = alpha[..., None] * d[..., :3] * rgb_t[0]
    if spec.mode == "additive":
        if spec.normalize == "time":
            n = a_t[0] * rgb_t[0]
        else:
            n = np.full(3, colour.max() if colour.size else 0.0)
        colour = np.where(n > 0, colour / np.where(n > 0, n, 1), 0)
        colour = np.minimum(colour, alpha[..., None])
    expected = np.concatenate([colour, alpha[..., None]], axis=-1)
    if spec.mode == "first_hit":
        hit = alpha > spec.threshold
        expected = np.where(hit[..., None], expected, 0)
        np.testing.assert_array_equal(t_index, np.where(hit, sel.steps[0], -1))
    elif spec.mode in ("max", "min"):
        np.testing.assert_array_equal(t_index, sel.steps[0])
    elif spec.mode == "count":
        f = (alpha > spec.threshold).astype(np.float64)
        d = lut_lookup(spec.data_tf.lut, f)
        expected = np.concatenate([d[..., :3] * d[..., 3:], d[..., 3:]], axis=-1)
    elif spec.mode == "change":
        expected = np.zeros_like(expected)
        np.testing.assert_array_equal(t_index, -1)
    else:
        assert spec.mode in ("alpha", "additive", "mean"), f"add the W = 1 case of {spec.mode}"
    np.testing.assert_allclose(rgba, expected, atol=1e-6)


@given(st.data())
def test_alpha_is_associative_and_backward_is_reversed(data):
    """Invariant 2: integrate(S1 ++ S2) = over(S1, S2); backward = forward over reversed S."""
    u, sel = data.draw(windows(max_w=12))
    spec = data.draw(specs(mode="alpha", positions="absolute"))
    fwd = IntegrationSpec(**{**spec.__dict__, "order": "forward"})
    bwd = IntegrationSpec(**{**spec.__dict__, "order": "backward"})
    cut = data.draw(st.integers(0, sel.width))
    whole, _ = ref(u, sel, fwd)
    if 0 < cut < sel.width:
        s1, s2 = Selection(sel.steps[:cut], sel.n_steps), Selection(sel.steps[cut:], sel.n_steps)
        front, _ = ref(u[:cut], s1, fwd)
        back, _ = ref(u[cut:], s2, fwd)
        np.testing.assert_allclose(whole, reference.over(front, back), atol=1e-6)
        b_front, _ = ref(u[cut:], s2, bwd)
        b_back, _ = ref(u[:cut], s1, bwd)
        np.testing.assert_allclose(ref(u, sel, bwd)[0], reference.over(b_front, b_back), atol=1e-6)
    reversed_spec = IntegrationSpec(**{**spec.__dict__, "order": tuple(reversed(sel.steps))})
    np.testing.assert_array_equal(ref(u, sel, bwd)[0], ref(u, sel, reversed_spec)[0])


@given(st.data())
def test_additive_ignores_order(data):
    """Invariant 5a: additive is invariant under any order."""
    u, sel = data.draw(windows(max_w=12))
    spec = data.draw(specs(mode="additive"))
    perm = tuple(data.draw(st.permutations(sel.steps)))
    base, _ = ref(u, sel, IntegrationSpec(**{**spec.__dict__, "order": "forward"}))
    other, _ = ref(u, sel, IntegrationSpec(**{**spec.__dict__, "order": perm}))
    np.testing.assert_allclose(base, other, atol=1e-6)


@given(st.data())
def test_additive_full_overlap_is_white(data):
    """Invariant 5b: every step present with data alpha 1 and white data colour -> white."""
    u, sel = data.draw(windows(max_w=12).filter(lambda w: w[1].width >= 3))
    alpha = data.draw(
        st.sampled_from(
            [TimeAlpha("constant", value=1.0), TimeAlpha("hat", center=0.5, width=1.2, floor=0.3)]
        )
    )
    spec = IntegrationSpec(
        mode="additive",
        data_tf=DataTF(points=[(0, 1, 1, 1, 1), (1, 1, 1, 1, 1)]),
        time_tf=TimeTF(alpha=alpha, positions="relative"),
        order=data.draw(st.sampled_from(["forward", "backward"])),
    )
    rgba, _ = ref(u, sel, spec)
    a_max = spec.time_tf.evaluate(spec.time_tf.positions_of(sel.steps, sel.n_steps))[1].max()
    np.testing.assert_allclose(rgba[..., 3], a_max, atol=1e-6)
    np.testing.assert_allclose(rgba[..., :3], a_max, atol=1e-6)  # white at that opacity
    if alpha.shape == "constant":
        np.testing.assert_allclose(rgba, 1.0, atol=1e-6)


@given(st.data())
def test_z_slabs_with_halo_equal_the_whole_volume(data):
    """Invariant 3: integrating z-slabs of any size (with gradient halo) equals the whole."""
    u, sel = data.draw(windows(max_w=8))
    spec = data.draw(specs(selection=sel))
    slab = data.draw(st.integers(1, u.shape[1] + 1))
    # Values already in [0, 1] with 0 and 1 present, so the series' normalisation is the identity.
    raw = np.zeros((sel.n_steps, *u.shape[1:]), dtype=np.float32)
    raw[list(sel.steps)] = u
    raw[0].flat[0], raw[-1].flat[-1] = 0.0, 1.0
    series = TimeSeries.from_array(raw)
    u_all = series.normalized(sel.steps)
    whole, t_whole = ref(u_all, sel, spec)
    cv = integrate(series, sel, spec=spec, slab=slab, engine="numpy")
    np.testing.assert_allclose(cv.rgba, whole, atol=1e-6)
    if spec.has_t_index:
        np.testing.assert_array_equal(cv.t_index, t_whole)
    else:
        assert cv.t_index is None
