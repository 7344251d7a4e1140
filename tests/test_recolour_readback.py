"""A TF edit recoloured by the GPU's compute pass leaves its RGBA in the view's texture: it is
read back only when something reads it (a probe, a save, framing), never for edits nobody
read (issue 47). A WebSocket client of a real server; the compute pass runs on llvmpipe when
the viewer is told its GL is not a software one (as tests/test_recolour_viewer.py's "gpu")."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from chronocl.core.selection import Selection
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import open_series
from chronocl.integration.inmemory import integrate
from chronocl.viewer import recolouring

from .test_recolour_viewer import _opaque_from, _open_in, _sharp
from .test_viewer_server import get
from .viewer_helpers import Client, make_stores, serving


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    return make_stores(tmp_path_factory.mktemp("readback"))


@pytest.fixture(scope="module")
def server(stores):
    yield from serving(stores, gl_current=True)


@pytest.fixture
def reads(monkeypatch) -> list[int]:
    """The bytes of every texture read back (moderngl's `Texture3D.read_into`, the real one
    run), with the viewer's GL compute recolour forced on llvmpipe."""
    import moderngl

    got: list[int] = []
    real = moderngl.Texture3D.read_into

    def read_into(self, buffer, *args, **kwargs):
        got.append(np.asarray(buffer).nbytes)
        return real(self, buffer, *args, **kwargs)

    monkeypatch.setattr(moderngl.Texture3D, "read_into", read_into)
    monkeypatch.setattr(recolouring, "software_gl", lambda ctx: False)
    return got


def _saved(server, client: Client, folder) -> Chronovolume:
    """View 0's chronovolume as the page's Save chronovolume writes it, loaded back."""
    rid = client.send({"type": "save", "what": "chronovolume", "view": 0})
    _, dl = client.wait("download", rid)
    status, body, _ = get(server.base + dl["url"], {"X-Chronocl-Token": server.token})
    assert status == 200
    with zipfile.ZipFile(io.BytesIO(body)) as zf:
        zf.extractall(folder)
    return Chronovolume.load(folder)


def _as_integrated(store, cv: Chronovolume) -> None:
    """`cv`'s RGBA is what integrating its window under its spec gives: equal up to the
    rounding of two float32 evaluations of the same LUT (tests/test_recolour.py's bound)."""
    series = open_series(store)
    fresh = integrate(series, Selection(cv.steps, series.n_steps), spec=cv.spec)
    assert cv.rgba.dtype == np.float32 and fresh.rgba.shape == cv.rgba.shape
    np.testing.assert_allclose(cv.rgba, fresh.rgba, rtol=0, atol=1e-6)


def _edited_at(cv: Chronovolume) -> float:
    """Where `_opaque_from`'s edit that made `cv` puts the opacity's start."""
    return cv.metadata["spec"]["data_tf"]["points"][1][0]


def test_edits_nobody_reads_are_never_read_back(server, stores, reads, tmp_path) -> None:
    """Max-mode edits recoloured on the GPU read nothing back (each frame says readback_ms 0),
    nor does a camera move; a probe reads the last edit's RGBA back once, and a save after
    it reads nothing more; both see what integrating the edit gives. Framing (a camera
    reset) reads the next edit back, and that frame counts it."""
    client = Client(server)
    try:
        fitted, _ = _open_in(client, "max")
        timings = []
        for x in (0.01, 0.75, 0.6, 0.3):
            header, _ = _sharp(client, _opaque_from(x, fitted))
            timings.append(t := header["timings"])
            assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0, t
            assert reads == [], "an edit nobody read was read back"
        assert all(t.get("readback_ms") == 0 for t in timings), timings
        camera = {"azimuth": 30.0, "elevation": 20.0}
        header, _ = _sharp(client, {"camera": camera})
        assert reads == [] and header["timings"]["readback_ms"] == 0
        texture_bytes = 32**3 * 4 * 4  # the 32^3 vortex's float32 RGBA
        rid = client.send({"type": "probe", "x": 0.5, "y": 0.5})
        _, probed = client.wait("probe", rid)
        assert reads == [texture_bytes], reads
        saved = _saved(server, client, tmp_path / "a")
        assert reads == [texture_bytes], "the save read the texture again"
        assert _edited_at(saved) == 0.3
        _as_integrated(stores[0], saved)

        # the probe met what the window integrated with the same TFs and camera meets
        _sharp(client, {"window": {"t0": 0, "t1": 4}})
        header, _ = _sharp(client, {"window": {"t0": 1, "t1": 11}})
        assert header["timings"]["integrate_ms"] > 0 and header["timings"]["recolour_ms"] == 0
        rid = client.send({"type": "probe", "x": 0.5, "y": 0.5})
        _, again = client.wait("probe", rid)
        assert probed["voxel"] is not None and probed["voxel"] == again["voxel"], (probed, again)
        assert abs(probed["opacity"] - again["opacity"]) <= 1e-3, (probed, again)
        assert len(reads) == 1

        header, _ = _sharp(client, _opaque_from(0.5, fitted))
        t = header["timings"]
        assert t["recolour_ms"] > 0 and t["readback_ms"] == 0 and len(reads) == 1, t
        header, _ = _sharp(client, {"camera": {"azimuth": 10.0}, "refocus": True})
        assert len(reads) == 2 and header["timings"]["readback_ms"] > 0, header["timings"]
        saved = _saved(server, client, tmp_path / "b")
        assert len(reads) == 2 and _edited_at(saved) == 0.5
        _as_integrated(stores[0], saved)
    finally:
        client.close()


def test_a_recoloured_frame_something_holds_keeps_its_own_rgba(
    server, stores, reads, monkeypatch
) -> None:
    """A recoloured chronovolume that something still holds when its texture takes another
    frame (here the test, as a caller holding a view's chronovolume would) is read back
    first, in that frame (its readback_ms): by the next edit's recolour, or by the upload of
    another window integrated; each keeps its own edit's RGBA."""
    held: list[Chronovolume] = []
    real = recolouring.Recolouring.view

    def view(self, slot, spec, sel):
        cv = real(self, slot, spec, sel)
        if cv is not None:
            held.append(cv)
        return cv

    monkeypatch.setattr(recolouring.Recolouring, "view", view)
    client = Client(server)
    try:
        fitted, _ = _open_in(client, "max")
        header, _ = _sharp(client, _opaque_from(0.75, fitted))
        assert header["timings"]["readback_ms"] == 0 and reads == []
        header, _ = _sharp(client, _opaque_from(0.3, fitted))
        assert header["timings"]["readback_ms"] > 0 and len(reads) == 1, header["timings"]
        # another window integrated: its upload rewrites the texture, the held edit read first
        rid = client.send({"type": "update", "window": {"t0": 0, "t1": 4}})
        t = client.frame_for(rid)[1]["timings"]
        assert t["integrate_ms"] > 0 and t["readback_ms"] > 0 and len(reads) == 2, t
        assert [_edited_at(cv) for cv in held] == [0.75, 0.3]
        for cv in held:
            _as_integrated(stores[0], cv)
        assert len(reads) == 2
    finally:
        client.close()


def test_a_probe_between_edits_keeps_the_next_edit_recoloured_where_slabs_are_written(
    server, stores, reads, monkeypatch
) -> None:
    """Where a refine writes its texture slab by slab (a GPU engine's `slab_upload.pays`,
    forced here), a probe after a GPU recolour asks for the full-resolution frame, which is
    there already: nothing is rewritten, so the recolour still owns the texture and the next
    edit recolours it (a first version settled the frame there and integrated that edit)."""
    monkeypatch.setenv("CHRONOCL_SLAB_UPLOAD", "1")
    client = Client(server)
    try:
        fitted, _ = _open_in(client, "max")
        _sharp(client, _opaque_from(0.75, fitted))
        rid = client.send({"type": "probe", "x": 0.5, "y": 0.5})
        client.wait("probe", rid)
        header, _ = _sharp(client, _opaque_from(0.3, fitted))
        t = header["timings"]
        assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0, (t, header["views"])
    finally:
        client.close()
