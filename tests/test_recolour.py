"""Recolouring max, min, first_hit and change equals integrating the edited TF.

The winners (value and step per voxel) of a window integrated under one spec, recoloured under
another on the GPU (chronocl/render/recolour/gl.py) or the OpenCL device brick by brick
(recolour/bricks.py), give the display texture, its occupied box and brick grid, and the
picture that integrating the other spec gives (the render tests' tolerance), including after
slides both ways; `why_not` lets through only edits that cannot change who won.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from chronocl import reference
from chronocl.core.enhance import Enhance
from chronocl.core.errors import SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.core.memory import aligned_empty, recycled_empty, spares
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TimeAlpha, TimeTF
from chronocl.core.tuning import TUNING
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.engine.numpy import NumpyEngine
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration.inmemory import integrate
from chronocl.integration.interactive.session import Session
from chronocl.integration.interactive.winners import (
    RECOLOURED,
    Winners,
    recoloured,
    same_hits,
    why_not,
    winners,
)
from chronocl.modes.spec import IntegrationSpec
from chronocl.render import brick_grid
from chronocl.render.camera import Camera
from chronocl.render.raycaster import Raycaster
from chronocl.render.recolour import show
from chronocl.render.recolour.bricks import BrickRecolourer, shown_output
from chronocl.render.recolour.gl import GLRecolourer, available
from chronocl.render.upload import convert, display_format

from .strategies import data_tfs, examples, specs, time_tfs
from .test_slots import slotted_windows

UNIT = (0.0, 1.0)


@pytest.fixture(scope="module")
def gl():
    rc = Raycaster()
    if not available(rc.ctx):
        pytest.skip("this OpenGL has no compute shaders (4.3)")
    rec = GLRecolourer(rc.ctx)
    yield rc, rec
    rec.release()


def _spec(mode, data_tf, time_tf, order="forward", threshold=0.0, value_range=UNIT):
    tf = dataclasses.replace(data_tf, value_range=value_range)
    return IntegrationSpec(mode=mode, order=order, data_tf=tf, time_tf=time_tf, threshold=threshold)


def _texture(vol) -> np.ndarray:
    nx, ny, nz = vol.texture.size
    dtype = np.uint8 if vol.texture.dtype == "f1" else np.float32
    return np.frombuffer(vol.texture.read(), dtype=dtype).reshape(nz, ny, nx, 4)


def _same_picture(rc, got_vol, rgba: np.ndarray, spacing=(1.0, 1.0, 1.0), fmt=None) -> None:
    """`got_vol` (recoloured) draws as the integrated `rgba` does, uploaded in the viewer's
    format (or `fmt`): the render tests' tolerance (max 8, at most 1 % of pixels over 3)."""
    fmt = fmt or display_format(rgba[..., 0].size)
    meta = {"spacing": dict(zip("xyz", spacing, strict=True))}
    want_vol = rc.upload(Chronovolume(rgba, None, meta), dtype=fmt)
    data, _ = convert(rgba, fmt)
    np.testing.assert_allclose(_texture(got_vol), data, rtol=0, atol=1 if fmt == "f1" else 1e-6)
    for name, a, b in (
        ("occupied min", *[v.occupied[0] for v in (got_vol, want_vol)]),
        ("occupied max", *[v.occupied[1] for v in (got_vol, want_vol)]),
    ):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, err_msg=name)
    # the brick grid of empty-space skipping: empty exactly where the integrated one is
    gx, gy, gz = got_vol.bricks.size
    grid = np.frombuffer(got_vol.bricks.read(), dtype=np.uint8).reshape(gz, gy, gx)
    np.testing.assert_array_equal(grid > 0, brick_grid.from_rgba(data) > 0)
    for camera in (Camera(30, 20), Camera(-120, -40, projection="orthographic")):
        want = rc.draw(want_vol, camera, (48, 40), jitter=False)
        got = rc.draw(got_vol, camera, (48, 40), jitter=False)
        diff = np.abs(got.astype(int) - want.astype(int))
        assert diff.max() <= 8 and (diff > 3).mean() <= 0.01, (diff.max(), (diff > 3).mean())
    want_vol.release()


@settings(
    max_examples=examples(12),
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_recolour_equals_integrating_the_edit(gl, data) -> None:
    """Any TF edit `why_not` lets through, at odd shapes and W in 1..40: the recoloured
    texture and picture equal integrating the edited spec; first_hit edits it refuses do
    change who won somewhere, or could."""
    rc, rec = gl
    mode = data.draw(st.sampled_from(RECOLOURED))
    shape = data.draw(st.tuples(*[st.integers(5, 19)] * 3))
    width = data.draw(st.integers(1, 40))
    n_steps = width + data.draw(st.integers(0, 5))
    steps = tuple(range(n_steps - width, n_steps))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    raw = rng.random((width, *shape), dtype=np.float32)
    if data.draw(st.booleans()):  # exact ties: first in the order wins
        raw = (np.round(raw * 4) / 4).astype(np.float32)
    order = data.draw(st.sampled_from(["forward", "backward"]))
    threshold = data.draw(st.sampled_from([0.0, 0.1]))
    old = _spec(mode, data.draw(data_tfs()), data.draw(time_tfs()), order, threshold)
    new = _spec(mode, data.draw(data_tfs()), data.draw(time_tfs()), order, threshold)
    edit = data.draw(st.sampled_from(["any", "colour", "opacity"]))
    if mode == "first_hit" and edit == "colour":
        new = dataclasses.replace(new, data_tf=old.data_tf, time_tf=old.time_tf)
        # a colour-only edit keeps every opacity, so the hits
        pts = tuple((p[0], *rng.random(3), p[4]) for p in old.data_tf.points)
        new = dataclasses.replace(new, data_tf=dataclasses.replace(new.data_tf, points=pts))
    elif mode == "first_hit" and edit == "opacity":
        # opacity 0 below a cut, scaled elsewhere: the zeros stay, so at a threshold of 0 the
        # crossings from them stay where they were (`same_hits`), whatever the scale
        cut = rng.uniform(0.0, 0.6)
        pts = tuple((*p[:4], 0.0 if p[0] < cut else p[4]) for p in old.data_tf.points)
        old = dataclasses.replace(old, data_tf=dataclasses.replace(old.data_tf, points=pts))
        pts = tuple((*p[:4], min(1.0, p[4] * rng.uniform(0.2, 1.5))) for p in pts)
        tf = dataclasses.replace(old.data_tf, points=pts)
        new = dataclasses.replace(new, data_tf=tf, time_tf=old.time_tf)
    order_idx = np.arange(width) if order == "forward" else np.arange(width)[::-1]

    def run(spec):
        pos = spec.time_tf.positions_of(steps, n_steps)
        return reference.integrate(raw, steps, pos, order_idx, spec)

    _, t_index = run(old)
    reason = why_not(old, new, UNIT, UNIT, steps, n_steps)
    if reason is not None:
        assert mode == "first_hit" and not same_hits(old, new, steps, n_steps)
        return
    want, want_t = run(new)
    np.testing.assert_array_equal(want_t, t_index)  # the winners did not change
    w = winners(t_index, dict(zip(steps, raw, strict=True)), steps, n_steps, UNIT, old)
    np.testing.assert_allclose(recoloured(w, new), want, rtol=0, atol=1e-6)
    prepared = rec.prepare(w)
    try:
        _same_picture(rc, _on_gpu(rc, rec, prepared, new, (1.0, 1.0, 1.0)), want)
    finally:
        prepared.release()
    _same_on_host(w, new, want)
    mid = _spec(mode, data.draw(data_tfs()), data.draw(time_tfs()), order, threshold)
    if why_not(old, mid, UNIT, UNIT, steps, n_steps) is None:
        _same_by_bricks(rc, w, [old, mid, new], run(old)[0], want)


def test_first_hit_opacity_edits_that_keep_the_zeros_keep_the_hits() -> None:
    """At a threshold of 0, an opacity edit that keeps the TF's zeros keeps who hits
    (`same_hits`): the viewer's default TF with its middle point's opacity moved (the page's
    usual edit) recolours, and values a float32 step past the zero entry, or short of it,
    hit or miss alike under both, on the numpy reference and the OpenCL kernels. A rise from
    the first entry, or a threshold above 0, still integrates."""
    size = DataTF().size
    first_live = next(i for i, a in enumerate(DataTF().lut[:, 3]) if a > 0)  # 13 of 256
    zero = np.float32((first_live - 1) / (size - 1))  # the last entry at 0
    u = [zero]
    for _ in range(4):  # the least float32 steps either side of the crossing
        u += [np.nextafter(u[-1], np.float32(1)), np.nextafter(u[0], np.float32(0))]
    u = np.array(sorted(u) * 3, dtype=np.float32)[:27].reshape(3, 3, 3)
    n_steps, steps = 3, (0, 1, 2)
    raw = np.stack([u, np.flip(u), u + np.float32(0.3)])
    tf_old = DataTF(value_range=UNIT)
    for opacity in (0.05, 0.9):
        pts = [list(p) for p in DataTF().points]
        pts[2][4] = opacity
        tf_new = DataTF(points=tuple(map(tuple, pts)), value_range=UNIT)
        old, new = (_spec("first_hit", tf, TimeTF()) for tf in (tf_old, tf_new))
        assert same_hits(old, new, steps, n_steps)
        assert why_not(old, new, UNIT, UNIT, steps, n_steps) is None
        pos = TimeTF().positions_of(steps, n_steps)
        t_old = reference.integrate(raw, steps, pos, np.arange(3), old)[1]
        t_new = reference.integrate(raw, steps, pos, np.arange(3), new)[1]
        np.testing.assert_array_equal(t_old, t_new)
        series = TimeSeries.from_array(raw)
        sel = Selection(steps, n_steps)
        got = [integrate(series, sel, spec=s, engine="opencl") for s in (old, new)]
        np.testing.assert_array_equal(got[0].t_index, t_old)
        np.testing.assert_array_equal(got[1].t_index, t_old)
    ramp = DataTF(points=((0, 1, 1, 1, 0.0), (1, 1, 1, 1, 0.5)), value_range=UNIT)
    steeper = DataTF(points=((0, 1, 1, 1, 0.0), (1, 1, 1, 1, 0.9)), value_range=UNIT)
    old, new = (_spec("first_hit", tf, TimeTF()) for tf in (ramp, steeper))
    assert not same_hits(old, new, steps, n_steps)  # from entry 0: f = u * 255 may underflow
    old, new = (_spec("first_hit", tf, TimeTF(), threshold=0.01) for tf in (tf_old, tf_new))
    assert not same_hits(old, new, steps, n_steps)  # the crossing moves with the opacity


def test_first_hit_edits_just_past_the_threshold_integrate() -> None:
    """An edit whose segments both pass (or both fail) the threshold at their ends, but by less
    than the rounding of lo * (1 - f) + hi * f and the time opacity's product may take away
    (`CLEAR_BY`), integrates: opacity 1 everywhere edited to just above a threshold of 0.5, or
    back, or from just below to further below; an edit that clears it by far recolours."""
    steps, n_steps = (0, 1), 2

    def flat(a: float) -> IntegrationSpec:
        tf = DataTF(points=((0, 1, 1, 1, a), (1, 1, 1, 1, a)), value_range=UNIT)
        return _spec("first_hit", tf, TimeTF(), threshold=0.5)

    just_above = float(np.nextafter(np.float32(0.5), np.float32(1)))
    just_below = float(np.nextafter(np.float32(0.5), np.float32(0)))
    for a, b in [(1.0, just_above), (just_above, 1.0), (just_below, 0.2)]:
        assert not same_hits(flat(a), flat(b), steps, n_steps), (a, b)
    assert same_hits(flat(1.0), flat(0.6), steps, n_steps)
    assert same_hits(flat(0.2), flat(0.4), steps, n_steps)


def _on_gpu(rc, rec, prepared, spec, spacing, into=None):
    """The GPU's recolouring of `prepared` under `spec`, shown in `into` (None: its own)."""
    changed = rec.apply(prepared, spec, into)
    show(changed, spacing)
    return changed.volume


def _whole(w, spec) -> np.ndarray:
    """The brick-wise recolouring of `w` under `spec` into an output of its own (zeroed: every
    brick it may colour written), a copy: the whole recolouring."""
    bricks = BrickRecolourer()
    prepared = bricks.prepare(w)
    try:
        return bricks.apply(prepared, spec).rgba.copy()
    finally:
        prepared.release()


def _same_by_bricks(rc, w, specs, first: np.ndarray, want: np.ndarray) -> None:
    """llvmpipe's brick-wise recolouring (recolour/bricks.py): edits in turn into one RGBA8
    texture holding the integrated `first`, each writing what changed since the one before
    (the last writes into the first's array again); the last equals the integrated `want`."""
    bricks = BrickRecolourer()
    prepared = bricks.prepare(w)
    vol = rc.upload(Chronovolume(first, None, {}), dtype="f1")
    try:
        held = None
        for spec in specs:
            changed = bricks.apply(prepared, spec, vol)
            show(changed, (1.0, 1.0, 1.0), held)
            held = changed.coloured
        data, _ = convert(want, "f1")
        np.testing.assert_allclose(changed.rgba, data, rtol=0, atol=1)
        # to the bit: the whole recolouring of the last spec (no brick left over)
        np.testing.assert_array_equal(changed.rgba, _whole(w, specs[-1]))
        _same_picture(rc, vol, want, fmt="f1")
    finally:
        vol.release()
        prepared.release()


def _same_on_host(w, spec, want: np.ndarray) -> None:
    """The OpenCL recolouring (llvmpipe's path) gives the display texture's data too: within 1
    of the integrated RGBA8 (the recolouring's floats are not integration's)."""
    data, _ = convert(want, "f1")
    np.testing.assert_allclose(_whole(w, spec), data, rtol=0, atol=1)


def _series(rng, n_steps: int, shape) -> TimeSeries:
    data = (rng.random((n_steps, *shape), dtype=np.float32) * 40 - 10).astype(np.float32)
    return TimeSeries.from_array(data)


@pytest.mark.parametrize("mode", RECOLOURED)
def test_session_recolours_after_slides_both_ways(gl, mode) -> None:
    """A session's window, slid forward and back (incrementally), recoloured under an edited
    TF equals integrating that window under it from scratch: at 41 x 37 x 43 (RGBA8 display
    texture) with spacing, on the OpenCL engine."""
    rc, rec = gl
    rng = np.random.default_rng(11)
    series = _series(rng, 14, (43, 37, 41))
    absolute = TimeTF(positions="absolute")
    vr = (-10.0, 30.0)  # the edit keeps the range: a hand-drawn opacity would take the series'
    spec = _spec(mode, DataTF(), absolute, value_range=vr)
    edit = _spec(
        mode,
        DataTF(points=((0, 0.2, 0.4, 1, 0.0), (0.4, 1, 0.5, 0, 0.3), (1, 1, 1, 0.2, 0.9))),
        TimeTF.preset("warm-cool", positions="absolute"),
        value_range=vr,
    )
    if mode == "first_hit":  # keep the hits: colours change, opacities stay
        edit = dataclasses.replace(
            edit, data_tf=dataclasses.replace(spec.data_tf, points=_recoloured_points(spec))
        )
    with Session(series, engine="opencl", spec=spec, memory="256MB") as s:
        s.set_window(2, 9)
        for move in (+2, -3, +1):
            s.slide(move)
            assert s.stats["path"] == "incremental"
            fixed = _recoloured(s, edit)
            w = s.at(0).winners()
            assert w is not None and w.steps == s.selection.steps
            want = integrate(series, s.selection, spec=fixed, engine="opencl")
            prepared = rec.prepare(w)
            try:
                _same_picture(rc, _on_gpu(rc, rec, prepared, fixed, series.spacing), want.rgba)
            finally:
                prepared.release()
            _same_on_host(w, fixed, want.rgba)


@pytest.mark.parametrize("mode", ["max", "min"])
def test_max_min_recolour_at_another_value_range(mode) -> None:
    """max/min's winners are the raw extremes: an edit of the value range recolours, with u
    gathered again at the new range, equal to integrating at it (issue 48); change refuses."""
    series = _series(np.random.default_rng(5), 9, (21, 17, 19))
    spec = _spec(mode, DataTF(), TimeTF(), value_range=(-10.0, 30.0))
    with Session(series, engine="opencl", spec=spec, memory="256MB") as s:
        s.set_window(1, 7)
        for vr in [(0.0, 12.0), (-4.0, 5.0)]:  # each clips many voxels to u = 0 or 1
            edit = _spec(mode, DataTF(), TimeTF.preset("warm-cool"), value_range=vr)
            fixed = _recoloured(s, edit)
            w = s.at(0).winners(vr)
            assert w.value_range == vr and w.steps == s.selection.steps
            want = integrate(series, s.selection, spec=fixed, engine="opencl")
            _same_on_host(w, fixed, want.rgba)
            s.set_spec(edit)  # the next edit starts from this range
            assert s.current().metadata["value_range"] == list(vr)
    change = _spec("change", DataTF(), TimeTF(), value_range=(-10.0, 30.0))
    steps, n = (1, 2, 3), 9
    assert "value range" in why_not(change, change, (-10.0, 30.0), (0.0, 12.0), steps, n)


def test_a_session_says_whether_an_edit_only_recolours_what_it_showed() -> None:
    """`Session.recolours`: the finest level's session, the edit fixed for its window and the
    value range it colours at where the edit only recolours the chronovolume shown; else one
    line saying why not."""
    series = _series(np.random.default_rng(3), 9, (13, 11, 12))
    spec = _spec("max", DataTF(), TimeTF(), value_range=(-10.0, 30.0))
    edit = _spec("max", DataTF(), TimeTF.preset("warm-cool"), value_range=(-10.0, 30.0))
    with Session(series, engine="opencl", spec=spec, memory="256MB") as s:
        shown = s.set_window(1, 7)
        sel = s.selection
        full, fixed, at = s.recolours(edit, sel, shown)
        assert s.at(0).recolours(edit) == (full, fixed, at)
        assert full is s.at(0) and fixed.time_tf == edit.time_tf and at == (-10.0, 30.0)
        wider = dataclasses.replace(edit, data_tf=DataTF(value_range=(-20.0, 40.0)))
        assert s.recolours(wider, sel, shown).value_range == (-20.0, 40.0)  # max: its own range
        assert s.recolours(edit, Selection((2, 3, 4), 9), shown) == "another window"
        other = Chronovolume(shown.rgba.copy(), shown.t_index, shown.metadata)
        assert s.recolours(edit, sel, other) == "the full-resolution window holds another frame"
        alpha = dataclasses.replace(edit, mode="alpha")
        assert s.recolours(alpha, sel, shown) == "the mode changed"
    coarse = _series(np.random.default_rng(3), 9, (5, 6, 70))  # 70: a coarse level (35)
    with Session(coarse, engine="opencl", spec=spec, memory="256MB", level="auto") as s:
        shown = s.set_window(1, 7)
        assert s.shown_level > 0  # a first window: the coarsest level
        assert s.recolours(edit, s.selection, shown) == "a coarse level is shown"
        shown = s.refine()  # at full resolution: it recolours
        full, fixed, _ = s.recolours(edit, s.selection, shown)
        assert full is s.at(0) and s.shown_level == 0


def _recoloured(s: Session, edit: IntegrationSpec) -> IntegrationSpec:
    """`edit` fixed for the window of `s`'s finest level, which it only recolours."""
    recolour = s.at(0).recolours(edit)
    assert not isinstance(recolour, str), recolour
    return recolour.spec


def _recoloured_points(spec):
    return tuple((p[0], 1.0 - p[1], 0.5, p[3] * 0.5, p[4]) for p in spec.data_tf.points)


def test_why_not_names_what_integrates() -> None:
    steps, n = (3, 4, 5), 8
    base = _spec("max", DataTF(), TimeTF())
    recolour = _spec("max", DataTF(points=((0, 1, 0, 0, 1), (1, 0, 0, 1, 0))), TimeTF.preset("rgb"))
    assert why_not(base, recolour, UNIT, UNIT, steps, n) is None
    assert "mixes" in why_not(_spec("alpha", DataTF(), TimeTF()), base, UNIT, UNIT, steps, n)
    assert "mode" in why_not(base, _spec("min", DataTF(), TimeTF()), UNIT, UNIT, steps, n)
    edge = dataclasses.replace(base, enhance=Enhance("edge", 0.5, 1.0, 1.0))
    assert "enhancement" in why_not(base, edge, UNIT, UNIT, steps, n)
    assert why_not(base, base, UNIT, (0.0, 2.0), steps, n) is None  # max: the same winners
    backward = dataclasses.replace(base, order="backward")
    assert "order" in why_not(base, backward, UNIT, UNIT, steps, n)
    hit = _spec("first_hit", DataTF(), TimeTF())
    colours = dataclasses.replace(
        hit, data_tf=dataclasses.replace(hit.data_tf, points=_recoloured_points(hit))
    )
    assert why_not(hit, colours, UNIT, UNIT, steps, n) is None
    # opacity zero at a step now: its voxels are no longer hit there
    hat = dataclasses.replace(hit, time_tf=TimeTF(alpha=TimeAlpha("hat", center=0.0, width=0.2)))
    assert "threshold" in why_not(hit, hat, UNIT, UNIT, steps, n)


@pytest.mark.parametrize("mode", RECOLOURED)
@pytest.mark.parametrize("dtype", [np.float32, np.uint8, np.int16, np.float64])
def test_opencl_gather_equals_the_numpy_one(mode, dtype, monkeypatch) -> None:
    """The winners gathered on the OpenCL device equal numpy's bit for bit: every data type
    it takes, windows over one and three chunks of steps, steps apart or in one block, values
    beyond the range clipped. Its arrays come with garbage in them (the memory of dead ones):
    the kernels write every voxel, those no step won included."""
    from chronocl.engine import gather as gather_module  # the module

    def dirty(shape, dtype):
        out = aligned_empty(shape, dtype)
        out.view(np.uint8)[...] = 0xFF  # NaN as float32
        return out

    rng = np.random.default_rng(5)
    for width in (1, 3, 9, 17):
        shape = (7, 9, 11)
        if dtype == np.uint8:
            raw = rng.integers(0, 256, (width, *shape)).astype(dtype)
        else:
            raw = (rng.random((width, *shape)) * 300 - 20).astype(dtype)
        steps, vr = tuple(range(2, 2 + width)), (10.0, 200.0)
        spec = _spec(mode, DataTF(), TimeTF(), value_range=vr)
        # change: the window's first step starts no change (its u is 0), though no change
        # integration picks it
        t_index = rng.choice(np.array([*steps, -1]), size=shape).astype(np.int32)
        # steps apart, and steps as views of one (Z, W, Y, X) block (the window manager's slots)
        block = aligned_empty((shape[0], width, *shape[1:]), dtype)
        block[...] = np.moveaxis(raw, 0, 1)
        for arrays in (
            dict(zip(steps, [aligned_copy(r) for r in raw], strict=True)),
            {s: block[:, i] for i, s in enumerate(steps)},
        ):
            want = winners(t_index, arrays, steps, 30, vr, spec)
            with monkeypatch.context() as m:
                m.setattr(gather_module, "recycled_empty", dirty)
                got = winners(t_index, arrays, steps, 30, vr, spec, OpenCLEngine())
            np.testing.assert_array_equal(got.k, want.k)
            np.testing.assert_array_equal(got.u, want.u)


@pytest.mark.parametrize("engine", [NumpyEngine, OpenCLEngine])
def test_a_gather_that_may_be_given_up_goes_in_pieces(engine) -> None:
    """Work that may be given up (the viewer's preparation at idle) gathers the winners in
    pieces (`TUNING.gather_pieces`), a checkpoint between two: new input gives it up at the
    next; unwatched, it gathers whole. Both engines' gathers, equal to numpy's either way."""
    rng = np.random.default_rng(9)
    shape, steps, vr = (40, 8, 8), (0, 1, 2, 3, 4), (0.0, 1.0)  # z rows of 64: slabs aligned
    arrays = {s: aligned_copy(rng.random(shape, dtype=np.float32)) for s in steps}
    t_index = rng.choice(np.array([*steps, -1], np.int32), size=shape)
    spec = _spec("max", DataTF(), TimeTF(), value_range=vr)
    want = winners(t_index, arrays, steps, 8, vr, spec)
    told: list[tuple] = []
    with interruptible(lambda: False, lambda *p: told.append(p)):
        got = winners(t_index, arrays, steps, 8, vr, spec, engine())
    np.testing.assert_array_equal(got.u, want.u)
    np.testing.assert_array_equal(got.k, want.k)
    assert 3 <= len(told) < TUNING.gather_pieces
    assert all(stage == "preparing the recolouring" for stage, _, _ in told)
    seen: list[tuple] = []
    with (
        pytest.raises(SupersededError),
        interruptible(lambda: len(seen) >= 2, lambda *p: seen.append(p)),
    ):
        winners(t_index, arrays, steps, 8, vr, spec, engine())
    assert len(seen) == 2  # given up at the third checkpoint


def aligned_copy(a: np.ndarray) -> np.ndarray:
    out = aligned_empty(a.shape, a.dtype)
    out[...] = a
    return out


@pytest.mark.parametrize("mode", RECOLOURED)
def test_recolouring_writes_into_the_rgba8_shown(mode) -> None:
    """The viewer's first edit of a window recolours into the RGBA8 the window shows (no second
    array): brick by brick, the bricks its spec may colour are rewritten with the first edit's,
    so an edit that leaves them transparent clears them; every edit equals the whole
    recolouring."""
    rng = np.random.default_rng(7)
    ramp = np.linspace(0, 1, 45, dtype=np.float32)  # values, and their changes, grow along x
    noise = rng.random((12, 37, 29, 45), dtype=np.float32)
    swing = 0.5 + 0.5 * (np.arange(12) % 2)[:, None, None, None]  # min, max and change alike
    data = -10 + 40 * ramp * swing * (0.8 + 0.2 * noise)
    series = TimeSeries.from_array(data.astype(np.float32))
    vr = (-10.0, 30.0)
    spec = _spec(mode, DataTF(), TimeTF(positions="absolute"), value_range=vr)
    high = ((0, 1, 1, 1, 0.0), (0.8, 1, 1, 1, 0.0), (1, 1, 1, 1, 1.0))  # opaque near 1 only
    edits = [
        _spec(mode, DataTF(points=pts), TimeTF.preset(c, positions="absolute"), value_range=vr)
        for pts, c in [(high, "rgb"), (DataTF().points, "warm-cool")]
    ]
    if mode == "first_hit":  # its edits keep every opacity (so the hits): colours only
        spec = _spec(mode, DataTF(points=high), TimeTF(positions="absolute"), "forward", 0.1, vr)
        pts = tuple((p[0], 0.2, 0.9, 0.4, p[4]) for p in high)
        edits = [
            dataclasses.replace(spec, data_tf=dataclasses.replace(spec.data_tf, points=pts)),
            dataclasses.replace(spec, time_tf=TimeTF.preset("warm-cool", positions="absolute")),
        ]
    with Session(series, engine="opencl", spec=spec, memory="256MB", display=True) as s:
        cv = s.set_window(2, 9)
        assert shown_output(cv.rgba, cv.shape)
        w = s.at(0).winners()
        bricks = BrickRecolourer()
        prepared = bricks.prepare(w, start=cv.rgba)
        try:
            before = prepared.output[1].copy()  # the bricks the shown spec may colour
            for edit in [*edits, spec]:
                fixed = _recoloured(s, edit)
                changed = bricks.apply(prepared, fixed)
                assert changed.rgba is cv.rgba
                np.testing.assert_array_equal(changed.rgba, _whole(w, fixed))
                if edit is edits[0] and mode != "first_hit":  # it cleared bricks shown
                    assert (before & ~changed.coloured).any()
        finally:
            prepared.release()


@pytest.mark.parametrize("mode", ["max", "change"])
def test_brick_outputs_taken_over_by_the_next_window_recolour_it_right(mode) -> None:
    """The viewer hands a window's brick-wise outputs (touched, with the bricks each may hold
    coloured) to the next window's winners: every edit of the next equals the whole
    recolouring, as with outputs of its own."""
    rng = np.random.default_rng(5)
    series = _series(rng, 12, (37, 29, 45))
    vr = (-10.0, 30.0)
    spec = _spec(mode, DataTF(), TimeTF(positions="absolute"), value_range=vr)
    edits = [
        _spec(mode, DataTF(points=pts), TimeTF.preset(c, positions="absolute"), value_range=vr)
        for pts, c in [
            (((0, 0.2, 0.4, 1, 0.0), (0.4, 1, 0.5, 0, 0.6), (1, 1, 1, 0.2, 0.9)), "warm-cool"),
            (((0, 1, 0, 0, 0.0), (0.8, 0, 1, 0, 0.0), (1, 1, 1, 1, 1.0)), "rgb"),
        ]
    ]
    with Session(series, engine="opencl", spec=spec, memory="256MB") as s:
        s.set_window(0, 6)
        bricks = BrickRecolourer()
        first = bricks.prepare(s.at(0).winners())
        for edit in edits:
            bricks.apply(first, _recoloured(s, edit))
        held = first.take_held()
        first.release()
        s.set_window(5, 11)
        w = s.at(0).winners()
        taken = bricks.prepare(w, held=held)
        try:
            assert taken.output[0] is held[0]
            for edit in [*edits[::-1], spec]:
                fixed = _recoloured(s, edit)
                np.testing.assert_array_equal(bricks.apply(taken, fixed).rgba, _whole(w, fixed))
        finally:
            taken.release()


def test_a_brick_output_of_its_own_comes_from_the_pool_zeroed_and_goes_back() -> None:
    """Winners with no output to take over recolour into one from the pool of reused host
    buffers (issue 47): the memory of a dead frame's array of its size, already faulted in,
    zeroed (its old contents must not show in bricks nothing colours), given back once the
    winners are released."""
    shape = (64, 256, 256)  # an RGBA8 output of 16 MiB: TUNING.mapped_bytes, pooled
    nbytes = int(np.prod(shape)) * 4
    assert nbytes >= TUNING.mapped_bytes
    rng = np.random.default_rng(11)
    u = np.zeros(shape, np.float32)
    k = np.full(shape, 255, np.uint8)  # no winner, but in one block
    u[20:30, 100:140, 60:90] = rng.random((10, 40, 30), dtype=np.float32)
    k[20:30, 100:140, 60:90] = rng.integers(0, 4, (10, 40, 30))
    spec = _spec("max", DataTF(), TimeTF())
    w = Winners(aligned_copy(u), aligned_copy(k), (0, 1, 2, 3), 4, UNIT, spec)
    spares.clear()
    dead = recycled_empty((*shape, 4), np.uint8)
    dead[...] = 7  # a dead frame's contents
    address = dead.ctypes.data
    del dead
    (given,) = [m for m in spares.maps if len(m) == nbytes]
    bricks = BrickRecolourer()
    prepared = bricks.prepare(w)
    try:
        assert prepared.output[0].ctypes.data == address
        assert not [m for m in spares.maps if len(m) == nbytes]
        want, _ = convert(recoloured(w, spec), "f1")
        np.testing.assert_allclose(bricks.apply(prepared, spec).rgba, want, rtol=0, atol=1)
    finally:
        prepared.release()
    assert any(m is given for m in spares.maps)  # back for the next frame


def test_a_recoloured_frame_and_its_winners_come_back_whole(monkeypatch) -> None:
    """A display frame of a recoloured mode holds three arrays of 4 bytes a voxel (RGBA8,
    t_index, the winners' u) and the winners' k: once they die (the view's window moves), the
    next window's frame and winners are made on all of that memory again, none on fresh pages
    (at 512^3 fresh pages for the winners cost 0.6 s of the first edit after a switch)."""
    import gc

    from chronocl.core.memory import spares
    from chronocl.core.selection import parse_selection

    monkeypatch.setattr(TUNING, "mapped_bytes", 1)  # small arrays recycled as large ones are
    misses: list[int] = []
    real = spares.take

    def take(size: int):
        got = real(size)
        if got is None:
            misses.append(size)
        return got

    monkeypatch.setattr(spares, "take", take)
    spares.clear()
    rng = np.random.default_rng(3)
    series = TimeSeries.from_array(rng.random((8, 40, 36, 44), dtype=np.float32))
    try:
        with Session(series, engine="opencl", mode="max", display=True, memory="256MB") as s:
            cv = s.set_window(0, 4)
            w = s.at(0).winners()
            assert cv.rgba.dtype == np.uint8 and misses  # the first frame: fresh memory
            misses.clear()
            s.leaving(parse_selection("4:8", 8))  # as the viewer does before a jump
            del cv, w
            gc.collect()
            s.set_window(4, 8)
            assert s.at(0).winners() is not None
            assert misses == []
    finally:
        spares.clear()


def test_the_first_edits_kernels_are_warmed_once_per_data_type(monkeypatch) -> None:
    """`warm_kernels` runs a first edit's kernels (both gathers, the brick summaries and
    recolour) on one brick, once per device and data type; the viewer calls it after its first
    frame (test_recolour_viewer.py checks that it does)."""
    from chronocl.render.recolour import bricks as recolour_bricks

    gathered, recoloured = [], []
    real_gather, real_apply = recolour_bricks.on_device, BrickRecolourer.apply

    def spy_gather(*args):
        gathered.append("change" if args[-1] else "max")
        return real_gather(*args)

    def spy_apply(self, prepared, spec, into=None):
        changed = real_apply(self, prepared, spec, into)
        recoloured.append(changed.rgba.shape)
        return changed

    def no_numpy(*args, **kwargs):
        raise AssertionError("warmed numpy's gather, not the OpenCL kernels")

    from chronocl.engine import gather as gather_module

    monkeypatch.setattr(gather_module, "on_host", no_numpy)
    monkeypatch.setattr(recolour_bricks, "on_device", spy_gather)
    monkeypatch.setattr(BrickRecolourer, "apply", spy_apply)
    monkeypatch.setattr(recolour_bricks, "_warmed", set())
    recolour_bricks.warm_kernels(np.uint16, None)
    b = brick_grid.BRICK
    assert gathered == ["max", "change"] and recoloured == [(b, b, b, 4)] * 2
    recolour_bricks.warm_kernels(np.uint16, None)
    assert len(gathered) == 2  # warm already
    recolour_bricks.warm_kernels(np.float32, None)
    assert len(gathered) == 4


@settings(max_examples=examples(16), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_the_kernels_winners_equal_the_gathered_ones(data) -> None:
    """max, min and change write each voxel's winner (u and step index) as they integrate,
    where asked (`integrate_bricks(winners=)`): bit for bit the winners gathered from the
    integrated t_index, on odd shapes, windows, slab splits, in place in the window manager's
    slots and stacked, the per-vector and the rows kernels, every x86 path, float32 and RGBA8
    output, float and integer data (compared in their own lanes)."""
    from chronocl.data.bricks import ResidentBricks
    from chronocl.integration.inmemory import WinnersOut, integrate_bricks, window_job

    series, sel, arrays = data.draw(slotted_windows())  # float32, uint8 or uint16 in slots
    spec = data.draw(
        specs(mode=data.draw(st.sampled_from(["max", "min", "change"])), selection=sel)
    )
    slab = data.draw(st.integers(1, series.volume_shape[0] + 1))
    engine = OpenCLEngine(
        host_ptr=data.draw(st.booleans()),  # in place, or copied
        row_blocks=data.draw(st.booleans()),  # the rows kernel, or the per-vector one
        cpu_paths=data.draw(st.sampled_from(["native", "avx2", "generic"])),
    )
    job = window_job(series, sel, spec)
    won = WinnersOut()
    display = data.draw(st.booleans())
    cv = integrate_bricks(
        job, engine, ResidentBricks(arrays), slab=slab, display=display, winners=won
    )
    assert won.u is not None and won.k is not None
    steps = sel.steps
    want = winners(cv.t_index, arrays, steps, series.n_steps, tuple(job.value_range), spec)
    np.testing.assert_array_equal(won.k, want.k)
    np.testing.assert_array_equal(won.u, want.u)
    # what the kernels integrate without winners is the same picture
    again = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab, display=display)
    np.testing.assert_array_equal(again.rgba, cv.rgba)
    np.testing.assert_array_equal(again.t_index, cv.t_index)


def test_a_session_keeps_the_kernels_winners_until_its_window_changes(monkeypatch) -> None:
    """A viewer's session (display) in max hands out the winners its integration wrote: no
    gather; after a slide or a value range they are gathered again; the numpy engine gathers."""
    gathered = []
    real = OpenCLEngine.gather

    def spy(self, *args, **kwargs):
        gathered.append(1)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(OpenCLEngine, "gather", spy)
    rng = np.random.default_rng(3)
    series = TimeSeries.from_array(rng.random((8, 5, 6, 21), dtype=np.float32))
    s = Session(series, memory="64MB", mode="max", display=True, time_tf="rgb")
    cv = s.set_window(1, 5)
    w = s.at(0).winners()
    assert not gathered and w is not None
    want = winners(
        cv.t_index,
        {t: series.host[t] for t in range(1, 5)},
        (1, 2, 3, 4),
        8,
        tuple(cv.metadata["value_range"]),
        s.spec,
    )
    np.testing.assert_array_equal(w.u, want.u)
    np.testing.assert_array_equal(w.k, want.k)
    assert w.spec == s.spec
    s.at(0).winners((0.2, 0.7))  # u at another range: gathered
    assert len(gathered) == 1
    cv = s.slide(1)  # slid (gathered) or integrated again (written): the new window's
    w = s.at(0).winners()
    assert len(gathered) == (2 if s.stats["path"] == "incremental" else 1)
    want = winners(
        cv.t_index,
        {t: series.host[t] for t in range(2, 6)},
        (2, 3, 4, 5),
        8,
        tuple(cv.metadata["value_range"]),
        s.spec,
    )
    np.testing.assert_array_equal(w.u, want.u)
    np.testing.assert_array_equal(w.k, want.k)
    s.close()
    gathered.clear()
    with Session(series, engine="numpy", memory="64MB", mode="max", time_tf="rgb") as s:
        cv = s.set_window(1, 5)
        w = s.at(0).winners()  # numpy's gather: no kernel writes winners
        assert not gathered and w.steps == (1, 2, 3, 4)
        arrays = {t: series.host[t] for t in range(1, 5)}
        want = winners(cv.t_index, arrays, (1, 2, 3, 4), 8, w.value_range, s.spec)
        np.testing.assert_array_equal(w.u, want.u)
        np.testing.assert_array_equal(w.k, want.k)


def test_the_bricks_rgba8_rounds_as_the_display_conversion() -> None:
    """The brick kernel's RGBA8 (its 2^23 rounding) is round(v * 255) half to even, clamped,
    as the display conversion rounds (and the integrate kernels' convert_uchar4_sat_rte), to
    the bit, ties included: winners on LUT entries (x = u * 256 exact, the lerp exact) and a
    time TF of 1, so each channel is a LUT entry times its opacity in one float32 product."""
    from types import SimpleNamespace

    rng = np.random.default_rng(3)
    n = 257
    lut = rng.random((n, 4), dtype=np.float32)
    lut[::2, 3] = 1.0  # opaque: the colours themselves, many of them ties
    lut[1::4, :3] = ((2 * rng.integers(0, 255, (len(lut[1::4]), 3)) + 1) / 510).astype(np.float32)
    lut[: n // 2 : 3, :3] = np.float32(0.5 / 255)  # a tie at 0.5: rounds to 0
    u = (rng.integers(0, n, (16, 16, 24)) / np.float32(n - 1)).astype(np.float32)
    steps = (0, 1, 2)
    k = rng.integers(0, 4, u.shape).astype(np.uint8)
    k[k == 3] = 255  # no winner
    time_tf = SimpleNamespace(
        positions_of=lambda steps, n_steps: np.zeros(len(steps)),
        evaluate=lambda pos: (np.ones((len(pos), 3)), np.ones(len(pos))),
    )
    spec = SimpleNamespace(data_tf=SimpleNamespace(lut=lut), time_tf=time_tf)
    w = Winners(u, k, steps, 3, UNIT, _spec("max", DataTF(), TimeTF()))
    d = lut[np.rint(u * (n - 1)).astype(int)]
    want = np.zeros((*u.shape, 4), np.float32)
    want[..., :3] = d[..., 3:] * d[..., :3]
    want[..., 3] = d[..., 3]
    want[k == 255] = 0
    exact, _ = convert(want, "f1")
    assert (np.modf(want * np.float32(255))[0] == 0.5).any()  # ties on the way
    np.testing.assert_array_equal(_whole(w, spec), exact)


def test_the_rgba8_rule_gives_the_bytes_of_the_saturating_rte_conversion() -> None:
    """rgba8.h, the one rule by which every kernel writes RGBA8 (a clamp and 2^23: the
    integrate kernels' store, four lanes and sixteen, and the brick recolouring's), equals
    convert_uchar4_sat_rte (round to nearest even, saturated: the host's conversion) on the
    OpenCL device for every float32 from -1 to 2 at a stride, every tie k + 0.5 and its
    neighbours, and the specials (NaN, infinities, -0, huge)."""
    import pyopencl as cl

    from chronocl.engine.device import get_context
    from chronocl.engine.program import RGBA8_H, build, source

    two = int(np.array(2.0, np.float32).view(np.int32))
    floats = np.arange(0, two, 61, dtype=np.int32).view(np.float32)  # 0 to 2
    floats = np.concatenate([floats, -floats[floats <= 1][::7]])  # and -1 to -0
    ties = (np.arange(256, dtype=np.float32) + np.float32(0.5)) / np.float32(255)
    near = [np.nextafter(ties, np.float32(d)) for d in (-1, 1)]
    special = np.array([np.nan, -np.nan, np.inf, -np.inf, -0.0, 3e38, -3e38, 1e-45], np.float32)
    values = np.concatenate([floats, ties, *near, special]).astype(np.float32)
    values = np.resize(values, (-(-values.size // 16), 16))
    kernel = """
__kernel void check(__global const float16 *v, __global uchar16 *sat, __global uchar4 *four,
                  __global uchar16 *sixteen)
{
    size_t i = get_global_id(0);
    sat[i] = convert_uchar16_sat_rte(v[i] * 255.0f);
    for (int j = 0; j < 4; ++j)
        four[4 * i + j] = rgba8(vload4(j, (__global const float *)(v + i)));
    sixteen[i] = bytes16(v[i]);
}
"""
    dc = get_context()
    text = source("recolour.h", common=False) + source(RGBA8_H, common=False) + kernel
    program = build(dc, "rgba8_check", {"RGBA8": True, "VEC": 16}, text=text)
    got = [np.empty(values.shape, np.uint8) for _ in range(3)]
    mf = cl.mem_flags
    v_buf = cl.Buffer(dc.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=values)
    bufs = [cl.Buffer(dc.context, mf.WRITE_ONLY, values.size) for _ in range(3)]
    cl.Kernel(program, "check")(dc.queue, (len(values),), None, v_buf, *bufs)
    for out, buf in zip(got, bufs, strict=True):
        cl.enqueue_copy(dc.queue, out, buf)
    dc.queue.finish()
    sat, four, sixteen = got
    np.testing.assert_array_equal(four, sat)
    np.testing.assert_array_equal(sixteen, sat)
    assert values.size > 4 * 10**6
