"""The engine writes the display format itself (issue 32, display-ready output).

A viewer's full-resolution frame is premultiplied RGBA8, the texture format the raycaster
samples: the OpenCL kernels write it (common.h's RGBA8 build) instead of float32 that the host
then converts. It must equal the host conversion (`chronocl.render.upload.convert`, "f1") of the
float32 result bit for bit, and the numpy reference's within one step of 255, on odd shapes,
windows, orders and slabs, in place and stacked; a session with `display` returns it for
windows integrated from their steps and float32 where it slides.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core.selection import Selection
from chronocl.core.time_tf import TimeTF
from chronocl.data.bricks import ResidentBricks
from chronocl.engine.opencl import OpenCLEngine
from chronocl.integration import inmemory
from chronocl.integration.inmemory import DISPLAY_VOXELS, integrate_bricks, window_job
from chronocl.integration.interactive.session import Session
from chronocl.render import upload
from chronocl.render.upload import convert
from chronocl.viewer.saving import full_precision

from .strategies import examples, specs
from .test_opencl import assert_same
from .test_slots import slotted_windows

pytestmark = pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")


@pytest.fixture(autouse=True, scope="module")
def rgba8_at_any_size():
    """The small volumes here get the display format too (the viewer's threshold is 32^3)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(inmemory, "DISPLAY_VOXELS", 0)
        yield


def as_rgba8(rgba: np.ndarray) -> np.ndarray:
    return convert(np.ascontiguousarray(rgba, dtype=np.float32), "f1")[0]


def assert_display_of(got: chronocl.Chronovolume, ref: chronocl.Chronovolume, exact: bool):
    assert got.rgba.dtype == np.uint8
    want = as_rgba8(ref.rgba)
    diff = np.abs(got.rgba.astype(np.int16) - want.astype(np.int16))
    assert int(diff.max(initial=0)) <= (0 if exact else 1)
    if ref.t_index is not None:
        np.testing.assert_array_equal(got.t_index, ref.t_index)


@settings(max_examples=examples(12), deadline=None)
@given(st.data())
def test_rgba8_from_the_kernels_equals_the_host_conversion(data):
    series, sel, arrays = data.draw(slotted_windows())
    spec = data.draw(specs(selection=sel))
    slab = data.draw(st.integers(1, series.volume_shape[0] + 1))
    engine = OpenCLEngine(host_ptr=data.draw(st.booleans()))  # in place, and stacked
    job = window_job(series, sel, spec)
    got = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab, display=True)
    floats = integrate_bricks(job, engine, ResidentBricks(arrays), slab=slab)
    if spec.integration.finalize_is_global(spec):  # finished over the whole volume: float32
        assert got.rgba.dtype == np.float32
        assert_same(got, floats)
        return
    assert_display_of(got, floats, exact=True)
    assert_display_of(got, chronocl.integrate(series, sel, spec=spec, engine="numpy"), False)


@pytest.mark.parametrize("mode", ["max", "alpha", "change"])
def test_a_display_session_integrates_rgba8_and_slides_in_float32(mode, tmp_path):
    rng = np.random.default_rng(5)
    path = tmp_path / "s.zarr"
    chronocl.TimeSeries.from_array(rng.random((12, 5, 7, 21), dtype=np.float32)).save(path)
    series = chronocl.open(path)
    rgb = TimeTF.preset("rgb", positions="absolute")  # so a slide is incremental
    with Session(series, mode=mode, time_tf=rgb, memory="64MB", display=True) as session:
        cv = session.set_window(2, 9)
        ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
        assert_display_of(cv, ref, exact=False)
        paths = set()
        for k in (1, 1, -2, 3):  # the sliding state is float32, and so are its windows
            cv = session.slide(k)
            ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
            paths.add(session.stats["path"])
            if session.stats["path"] == "incremental":
                assert_same(cv, ref)
            else:
                assert_display_of(cv, ref, exact=False)
        assert "incremental" in paths
        cv = session.set_spec(order="backward")
        ref = chronocl.integrate(series, session.window(), spec=session.spec, engine="numpy")
        assert_display_of(cv, ref, exact=False)
        # the viewer's download: the same window integrated again in float32
        again = full_precision(cv, series, session.engine, 2**20)  # slabs of a small budget
        assert again.rgba.dtype == np.float32
        assert_same(again, ref)


def test_a_display_chronovolume_saves_as_float32(tmp_path):
    rng = np.random.default_rng(1)
    series = chronocl.TimeSeries.from_array(rng.random((6, 4, 5, 17), dtype=np.float32))
    sel = Selection((0, 1, 2, 3), 6)
    job = window_job(series, sel, chronocl.make_spec("max"))
    engine = OpenCLEngine()
    arrays = {s: series.host[s] for s in sel.steps}
    cv = integrate_bricks(job, engine, ResidentBricks(arrays), display=True)
    back = chronocl.Chronovolume.load(cv.save(tmp_path / "cv.zarr"))
    assert back.rgba.dtype == np.float32
    np.testing.assert_array_equal(back.rgba, cv.rgba.astype(np.float32) / np.float32(255))


def test_small_volumes_stay_float32_as_the_viewer_shows_them(monkeypatch):
    """Below the viewer's RGBA8 size its textures are float32: display frames stay float32 so a
    panel's format does not flip between integrated and slid frames."""
    monkeypatch.setattr(inmemory, "DISPLAY_VOXELS", DISPLAY_VOXELS)  # the module's fixture: 0
    assert upload.display_format(DISPLAY_VOXELS) == "f4"  # one size rule: the textures'
    assert upload.display_format(DISPLAY_VOXELS + 1) == "f1"
    rng = np.random.default_rng(2)
    series = chronocl.TimeSeries.from_array(rng.random((4, 8, 8, 8), dtype=np.float32))
    job = window_job(series, Selection((0, 1, 2), 4), chronocl.make_spec("max"))
    arrays = {s: series.host[s] for s in range(4)}
    cv = integrate_bricks(job, OpenCLEngine(), ResidentBricks(arrays), display=True)
    assert cv.rgba.dtype == np.float32
