"""A refine's texture written slab by slab while it integrates (`chronocl.viewer.slab_upload`):
the texture holds the chronovolume's RGBA8 bit for bit, the frame's upload writes nothing more
and draws what a whole upload draws; a refine given up half way is written whole next time."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import SupersededError
from chronocl.core.interrupt import interruptible
from chronocl.core.slab_sink import slabs_to
from chronocl.core.tuning import TUNING
from chronocl.data import synthetic
from chronocl.integration.interactive.session import Session
from chronocl.render import Camera
from chronocl.render.volume import Volume
from chronocl.viewer.gl_thread import on_gl
from chronocl.viewer.slab_upload import SlabUpload
from chronocl.viewer.slots import ViewSlot, upload

CAMERA = Camera(azimuth=30.0, elevation=20.0, zoom=1.2)
SHAPE = (37, 41, 43)  # above the viewer's RGBA8 size (32^3): a display chronovolume is RGBA8


@pytest.fixture(scope="module")
def series() -> chronocl.TimeSeries:
    return chronocl.TimeSeries.from_array(np.stack(list(synthetic.steps("vortex", 9, SHAPE))))


@pytest.fixture
def writes_counted(monkeypatch) -> list[tuple[Volume, int]]:
    """The volume and z-extent of every whole write `upload` makes."""
    calls: list[tuple[Volume, int]] = []
    write = Volume.write

    def counted(vol, data, given_up=None):
        calls.append((vol, data.shape[0]))
        return write(vol, data, given_up)

    monkeypatch.setattr(Volume, "write", counted)
    return calls


def texture_and_pictures(slot: ViewSlot, cv: chronocl.Chronovolume):
    """On the GL thread: the frame's upload into `slot`, the texture's bytes, its picture and
    the picture of a whole upload into a fresh slot."""

    def run(rc):
        vol = upload(rc, slot, cv)
        data = np.frombuffer(vol.texture.read(), np.uint8).reshape(cv.rgba.shape)
        fresh = ViewSlot()
        whole = upload(rc, fresh, cv)
        a = rc.draw(vol, CAMERA, (96, 96), jitter=False)
        b = rc.draw(whole, CAMERA, (96, 96), jitter=False)
        fresh.release_gl()
        return data, a, b

    return on_gl(run)


@pytest.mark.parametrize("mode", ["alpha", "max"])
def test_slabs_written_while_integrating_draw_what_a_whole_upload_draws(
    series, writes_counted, mode
):
    slot = ViewSlot()
    coarse = chronocl.integrate(series, "0:2", mode)  # float32: another format
    on_gl(lambda rc: upload(rc, slot, coarse))  # a float32 texture of another format shown
    writes_counted.clear()
    with Session(series, mode=mode, display=True, memory="256MB") as session:
        writes = SlabUpload(slot)
        with interruptible(lambda: False), slabs_to(writes.put):
            cv = session.set_window(1, 8)
        writes.done(cv)
    assert cv.rgba.dtype == np.uint8
    assert len(writes.jobs) == -(-SHAPE[0] // -(-SHAPE[0] // TUNING.refine_slabs)) > 1
    assert slot.written is cv and slot.uploaded is None
    data, a, b = texture_and_pictures(slot, cv)
    assert [n for vol, n in writes_counted if vol is slot.volume] == []  # not written again
    np.testing.assert_array_equal(data, cv.rgba)
    np.testing.assert_array_equal(a, b)
    assert a.max() > 0 and slot.uploaded is cv and slot.written is None
    on_gl(lambda rc: slot.release_gl())


def test_a_refine_given_up_half_way_is_written_whole_next_time(series, writes_counted):
    slot = ViewSlot()
    writes = SlabUpload(slot)

    def given_up() -> bool:
        return writes.rows >= 2 * -(-SHAPE[0] // TUNING.refine_slabs)  # newer input after two slabs

    with Session(series, mode="alpha", display=True, memory="256MB") as session:
        with pytest.raises(SupersededError), interruptible(given_up), slabs_to(writes.put):
            session.set_window(1, 8)
        writes.done(None)
        assert 0 < writes.rows < SHAPE[0]
        assert slot.written is None and slot.uploaded is None  # half written: no picture's
        cv = session.set_window(1, 8)
    data, a, b = texture_and_pictures(slot, cv)
    assert [n for vol, n in writes_counted if vol is slot.volume] == [SHAPE[0]]  # written whole
    np.testing.assert_array_equal(data, cv.rgba)
    np.testing.assert_array_equal(a, b)
    on_gl(lambda rc: slot.release_gl())


def test_slabs_are_written_where_the_integration_leaves_the_cores_free(monkeypatch):
    from chronocl.engine.opencl import OpenCLEngine
    from chronocl.viewer.slab_upload import pays

    monkeypatch.delenv("CHRONOCL_SLAB_UPLOAD", raising=False)
    assert pays(OpenCLEngine(host_ptr=False), None)  # copies to its device, as a GPU's does
    assert not pays(OpenCLEngine(host_ptr=True), None)  # the host's cores: llvmpipe's too
    assert not pays("numpy", None)  # writes no display format
    monkeypatch.setenv("CHRONOCL_SLAB_UPLOAD", "1")
    assert pays("numpy", None)
    monkeypatch.setenv("CHRONOCL_SLAB_UPLOAD", "0")
    assert not pays(OpenCLEngine(host_ptr=False), None)
