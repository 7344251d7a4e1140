"""The viewer recolours a max-mode TF edit without integrating, and shows what integrating the
edit shows (a WebSocket client of a real server; tests/viewer_helpers.py)."""

from __future__ import annotations

import io
import time

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from chronocl.core.errors import SupersededError
from chronocl.core.interrupt import checkpoint
from chronocl.core.tuning import TUNING
from chronocl.engine.opencl import OpenCLEngine
from chronocl.viewer import recolouring

from .viewer_helpers import Client, connected_client, make_stores, serving  # noqa: F401

EDIT = {
    "data_tf": {"points": [[0, 0.2, 0.5, 1, 0], [0.3, 1, 0.6, 0, 0.4], [1, 1, 1, 1, 1]]},
    "time_tf": {"color": "warm-cool"},
}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    yield from serving(make_stores(tmp_path_factory.mktemp("recolour")), gl_current=True)


def _sharp(client: Client, msg: dict):
    """The full-resolution frame answering `msg` (its refine, where the first is coarse)."""
    rid = client.send({"type": "update", **msg})
    got = client.frame_for(rid)
    while got[1]["refining"]:
        got = client.wait("frame")
    return got[1], got[2]


def _open_in(client: Client, mode: str):
    """Open the data set at 96x96 and show `mode` at threshold 0, sharp: (the value range the
    page fitted, which it sends with an edit; the mode's sharp frame header)."""
    ds, _ = client.open(0, size=(96, 96))
    header, _ = _sharp(client, {"views": [{"mode": mode}], "threshold": 0.0})
    return ds["state"]["data_tf"]["value_range"], header


def _pixels(jpeg: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB")).astype(int)


def _assert_as_integrated(client: Client, recoloured: list) -> None:
    """The window (1:11) with the same TFs integrated, away and back (a recolour drops the
    sliding state), shows what the recoloured frame `recoloured` showed."""
    _sharp(client, {"window": {"t0": 0, "t1": 4}})
    header, integrated = _sharp(client, {"window": {"t0": 1, "t1": 11}})
    assert header["timings"]["integrate_ms"] > 0 and header["timings"]["recolour_ms"] == 0
    diff = np.abs(_pixels(recoloured[0]) - _pixels(integrated[0]))
    assert diff.mean() < 0.5 and np.percentile(diff, 99) <= 3, (diff.mean(), diff.max())


def _opaque_from(x: float, value_range) -> dict:
    """A max-mode edit with opacity from u = x on (and a little everywhere below x = 0.1)."""
    points = [[0, 0.2, 0.5, 1, 0.3 * (x < 0.1)], [x, 1, 0.6, 0, 0], [1, 1, 1, 1, 0.9]]
    return {"data_tf": {"points": points, "value_range": value_range}}


@pytest.mark.parametrize(
    ("mode", "where"), [("max", "host"), ("first_hit", "host"), ("max", "gpu")]
)
def test_tf_edit_recolours_without_integrating(client, monkeypatch, mode, where) -> None:
    """A TF edit in max mode (and first_hit, where it keeps who is hit) integrates nothing:
    the frame's split shows a recolour and no integration, at full resolution; the picture
    equals the one integrating the same window and TFs gives (after a window round trip).
    On llvmpipe the OpenCL device recolours ("host"); the GPU's compute pass ("gpu") runs on
    llvmpipe too when the viewer is told its GL is not a software one."""
    if where == "gpu":
        monkeypatch.setattr(recolouring, "software_gl", lambda ctx: False)
    fitted, header = _open_in(client, mode)
    assert header["level"] == 0 and header["timings"]["recolour_ms"] == 0
    edit = {**EDIT, "data_tf": {**EDIT["data_tf"], "value_range": fitted}}
    if mode == "first_hit":  # the same opacities (so the same hits), other colours
        white = [[0, 1, 1, 1, 0], [1, 1, 1, 1, 0.9]]
        _sharp(client, {"data_tf": {"points": white, "value_range": fitted}})
        coloured = [[0, 0.2, 0.5, 1, 0], [1, 1, 0.3, 0, 0.9]]
        edit = {"data_tf": {"points": coloured, "value_range": fitted}}
    header, recoloured = _sharp(client, edit)
    t = header["timings"]
    assert header["level"] == 0 and not header["refining"]
    assert header["views"][0]["why_integrated"] is None  # (where it integrated: why)
    assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0 and not t["incremental"]
    _assert_as_integrated(client, recoloured)


def test_edit_that_changes_the_hits_integrates(client) -> None:
    """first_hit: an edit making low values transparent changes which step is hit first, so
    the frame integrates."""
    fitted, _ = _open_in(client, "first_hit")
    cut = {"points": [[0, 1, 1, 1, 0], [0.6, 1, 1, 1, 0], [1, 1, 1, 1, 1]], "value_range": fitted}
    header, _ = _sharp(client, {"data_tf": cut})
    assert header["timings"]["recolour_ms"] == 0 and header["timings"]["integrate_ms"] > 0
    why = header["views"][0]["why_integrated"]
    assert why == "the edit changes which values pass the opacity threshold", why


@pytest.fixture(scope="module")
def rgba8_server(tmp_path_factory):
    """A vortex above 32^3 (odd sides), whose texture is RGBA8: llvmpipe's brick-wise path;
    and a second data set of its shape (another run of the simulation)."""
    from chronocl.data import synthetic
    from chronocl.data.series import TimeSeries

    root = tmp_path_factory.mktemp("recolour8")
    data = np.stack(list(synthetic.steps("vortex", 12, (44, 36, 40))))
    TimeSeries.from_array(data, source="vortex").save(root / "vortex.zarr")
    TimeSeries.from_array(data[::-1][:10], source="vortex").save(root / "again.zarr")
    yield from serving([root / "vortex.zarr", root / "again.zarr"], gl_current=True)


def test_edits_recolour_brick_by_brick(rgba8_server, monkeypatch) -> None:
    """RGBA8 on llvmpipe: successive max-mode edits recolour the bricks they may colour, write
    only those into the texture (the split counts the write as upload), and each picture
    equals the one integrating the same window and TFs gives."""
    from chronocl.render.recolour.bricks import BrickRecolourer

    sparse = []
    real = BrickRecolourer.apply

    def counted(self, prepared, spec, into=None):
        changed = real(self, prepared, spec, into)
        if into is not None:  # a view's, not `warm_kernels`' (the first frame's, on the side)
            sparse.append(changed.rewritten / changed.coloured.size)
        return changed

    monkeypatch.setattr(BrickRecolourer, "apply", counted)
    client = Client(rgba8_server)
    try:
        fitted, _ = _open_in(client, "max")
        # opacity from x on: every brick coloured, then few (the others must be cleared)
        for x in (0.01, 0.75, 0.6):
            header, recoloured = _sharp(client, _opaque_from(x, fitted))
            t = header["timings"]
            assert header["level"] == 0 and t["integrate_ms"] == 0 and t["recolour_ms"] > 0
            assert t["upload_ms"] > 0
        assert len(sparse) == 3 and min(sparse) < 0.5, sparse  # transparent bricks left out
        _assert_as_integrated(client, recoloured)
    finally:
        client.close()


@pytest.mark.parametrize("where", ["host", "gpu"])
def test_a_value_range_edit_recolours_max(rgba8_server, monkeypatch, where) -> None:
    """max's winners are the raw extremes, whatever the range: after a TF edit, edits of the
    value range (narrower, then wider, each after another TF edit) integrate nothing, and the
    picture equals integrating the window at that range (issue 48). On llvmpipe's OpenCL
    device brick by brick ("host"), and through the GPU's compute pass ("gpu")."""
    if where == "gpu":
        monkeypatch.setattr(recolouring, "software_gl", lambda ctx: False)
    client = Client(rgba8_server)
    try:
        (lo, hi), _ = _open_in(client, "max")
        _sharp(client, _opaque_from(0.3, [lo, hi]))  # winners prepared at the fitted range
        for vr in ([lo, lo + 0.4 * (hi - lo)], [lo - (hi - lo), hi]):
            header, recoloured = _sharp(client, _opaque_from(0.3, vr))
            t = header["timings"]
            assert header["level"] == 0 and t["integrate_ms"] == 0 and t["recolour_ms"] > 0
            _sharp(client, _opaque_from(0.5, vr))
            header, recoloured = _sharp(client, _opaque_from(0.3, vr))
            assert header["timings"]["integrate_ms"] == 0
        _assert_as_integrated(client, recoloured)
    finally:
        client.close()


def test_the_first_edit_recolours_into_the_frame_shown(rgba8_server, monkeypatch) -> None:
    """RGBA8 on llvmpipe: the winners' first edit writes into the RGBA8 the integrated frame
    holds (no second array) and into the texture only the bricks it or the frame may colour:
    an edit that leaves bricks the frame coloured transparent clears them in the texture
    too, and shows what integrating it shows."""
    starts, outputs, texels = [], [], []
    real_on_host, real_apply = recolouring.on_host, recolouring.BrickRecolourer.apply
    real_write = recolouring._write

    def write(rc, changed, held, spacing):
        real_write(rc, changed, held, spacing)
        texture = changed.volume.texture.read()
        texels.append(np.frombuffer(texture, np.uint8).reshape(changed.rgba.shape))

    def on_host(w, device, held=None, start=None):
        starts.append(start)
        return real_on_host(w, device, held, start)

    def apply(self, prepared, spec, into=None):
        changed = real_apply(self, prepared, spec, into)
        if into is not None:  # a view's, not `warm_kernels`'
            outputs.append(changed)
        return changed

    monkeypatch.setattr(recolouring, "on_host", on_host)
    monkeypatch.setattr(recolouring.BrickRecolourer, "apply", apply)
    monkeypatch.setattr(recolouring, "_write", write)
    client = Client(rgba8_server)
    try:
        fitted, _ = _open_in(client, "max")
        header, recoloured = _sharp(client, _opaque_from(0.75, fitted))
        t = header["timings"]
        assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0
        assert len(starts) == 1 and starts[0] is not None
        assert len(outputs) == 1 and outputs[0].rgba is starts[0]
        assert 0 < outputs[0].rewritten < outputs[0].coloured.size  # the bricks it may change
        np.testing.assert_array_equal(texels[0], outputs[0].rgba)
        _assert_as_integrated(client, recoloured)
    finally:
        client.close()


def test_winners_over_the_devices_largest_buffer_recolour_in_spans(rgba8_server, monkeypatch):
    """RGBA8 on llvmpipe under an allocation cap the winners are over (at 1024^3 u alone is
    4 GB, over PoCL's 2-4 GB on a CPU; here `CHRONOCL_MAX_ALLOC` under the 44 x 36 x 40
    vortex's 253 KB of u, over two rows of its bricks): the brick recolouring holds them in
    z-spans of rows of bricks, so max-mode edits still recolour (the frame says so, nothing
    integrated) and show what integrating them shows."""
    from chronocl.engine import buffers

    spans: list[int] = []
    real = recolouring.on_host

    def on_host(w, device, held=None, start=None):
        prepared = real(w, device, held, start)
        spans.append(None if prepared is None else len(prepared.spans))
        return prepared

    monkeypatch.setattr(recolouring, "on_host", on_host)
    monkeypatch.setenv(buffers.MAX_ALLOC_VAR, "100KB")  # u 253 KB, a row of bricks 46 KB
    client = Client(rgba8_server)
    try:
        fitted, _ = _open_in(client, "max")
        for x in (0.01, 0.75):  # every brick coloured, then few
            header, recoloured = _sharp(client, _opaque_from(x, fitted))
            t = header["timings"]
            assert header["level"] == 0 and t["integrate_ms"] == 0 and t["recolour_ms"] > 0, t
            assert header["views"][0]["why_integrated"] is None
        assert spans and all(n == 3 for n in spans), spans
        _assert_as_integrated(client, recoloured)
    finally:
        client.close()


def test_a_recolouring_that_fails_part_way_leaves_the_next_edit_right(rgba8_server, monkeypatch):
    """RGBA8 on llvmpipe: an edit whose texture write fails after writing (the recolouring's
    one output, which the shown chronovolume wraps, and the texture then hold its colours) is
    answered with an error and the viewer keeps serving. The failure drops the view's session
    (`view_sessions.Views`), so nothing torn is taken as shown: the next edit integrates, and
    the one after recolours again, on the output the failed edit wrote (taken over with the
    bricks it may hold), and shows what integrating it shows."""
    real = recolouring._write
    failing = []

    def write(rc, changed, held, spacing):
        real(rc, changed, held, spacing)
        if failing:
            failing.clear()
            raise RuntimeError("injected after the texture write")

    monkeypatch.setattr(recolouring, "_write", write)
    client = Client(rgba8_server)
    try:
        fitted, _ = _open_in(client, "max")
        header, _ = _sharp(client, _opaque_from(0.75, fitted))  # few bricks coloured
        assert header["timings"]["recolour_ms"] > 0
        failing.append(True)
        every = _opaque_from(0.01, fitted)  # every brick, and it fails
        rid = client.send({"type": "update", **every})
        errors: list = []
        client.wait("error", rid, errors=errors)
        assert "injected after the texture write" in errors[-1]["message"], errors
        header, _ = _sharp(client, _opaque_from(0.7, fitted))
        assert header["timings"]["integrate_ms"] > 0  # nothing of the torn one is trusted
        header, recoloured = _sharp(client, _opaque_from(0.65, fitted))  # few again, recoloured
        t = header["timings"]
        assert header["level"] == 0 and t["integrate_ms"] == 0 and t["recolour_ms"] > 0
        _assert_as_integrated(client, recoloured)
    finally:
        client.close()


def _counting_gather(monkeypatch, hold_first: bool = False) -> list[str]:
    """Spy on the viewer's gathers of winners (the real one runs): each call's outcome. With
    `hold_first`, the first waits until new input has come (its checkpoints would give it up).
    The kernels write no winners meanwhile (max and change then gather, as first_hit does)."""

    monkeypatch.setattr(OpenCLEngine, "writes_winners", False)
    calls: list[str] = []
    real = OpenCLEngine.gather

    def input_came() -> bool:
        try:
            checkpoint("waiting for the test's input", 0, 1)
        except SupersededError:
            return True
        return False

    def spy(self, *args, **kwargs):
        calls.append("started")
        if hold_first and len(calls) == 1:
            _until(input_came)
        try:
            w = real(self, *args, **kwargs)
        except SupersededError:
            calls[-1] = "given up"
            raise
        calls[-1] = "done"
        return w

    monkeypatch.setattr(OpenCLEngine, "gather", spy)
    return calls


def _until(predicate, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while not predicate():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.02)


@pytest.mark.parametrize("mode", ["max", "change"])
def test_winners_are_gathered_at_idle_and_the_first_edit_only_recolours(
    client, monkeypatch, mode
) -> None:
    """A sharp frame of a recolouring mode, then no input: the viewer gathers its winners, and
    the first TF edit after the mode switch recolours without gathering again."""
    calls = _counting_gather(monkeypatch)
    fitted, _ = _open_in(client, mode)
    _until(lambda: calls == ["done"])
    edit = {**EDIT, "data_tf": {**EDIT["data_tf"], "value_range": fitted}}
    header, _ = _sharp(client, edit)
    t = header["timings"]
    assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0
    assert calls == ["done"], "the edit gathered the winners again"


def test_the_first_frame_warms_the_recolouring_kernels_on_the_side(client, monkeypatch):
    """After its first frame (alpha), the viewer runs a first edit's kernels once on its side
    thread (`warm_kernels`), so the first recolouring edit does not load them."""
    from chronocl.render.recolour import bricks as recolour_bricks

    warmed: set = set()
    monkeypatch.setattr(recolour_bricks, "_warmed", warmed)
    _open_in(client, "alpha")
    _until(lambda: (None, "float32") in warmed)


def test_an_idle_gather_is_given_up_by_new_input_and_the_edit_is_right(client, monkeypatch):
    """Input while the winners are gathered at idle gives the gather up at its next slab; the
    edit's frame recolours from a gather of its own and shows what integrating it shows."""
    calls = _counting_gather(monkeypatch, hold_first=True)
    fitted, _ = _open_in(client, "max")
    _until(lambda: calls == ["started"])  # the idle gather, held until the edit comes
    edit = {**EDIT, "data_tf": {**EDIT["data_tf"], "value_range": fitted}}
    rid = client.send({"type": "update", **edit})
    got = client.frame_for(rid)
    while got[1]["refining"]:
        got = client.wait("frame")
    header, recoloured = got[1], got[2]
    assert calls == ["given up", "done"], calls
    t = header["timings"]
    assert header["level"] == 0 and t["integrate_ms"] == 0 and t["recolour_ms"] > 0
    _assert_as_integrated(client, recoloured)


@pytest.mark.parametrize("mode", ["max", "change"])
def test_the_first_edit_after_a_switch_takes_the_winners_the_integration_wrote(
    client, monkeypatch, mode
) -> None:
    """max and change: the kernels wrote each voxel's winner as they integrated the switch's
    window, so neither the idle preparation nor the first edit gathers, and the edit shows what
    integrating it shows."""
    calls: list[str] = []
    monkeypatch.setattr(OpenCLEngine, "gather", lambda *a, **k: calls.append("gathered"))
    fitted, _ = _open_in(client, mode)
    edit = {**EDIT, "data_tf": {**EDIT["data_tf"], "value_range": fitted}}
    header, recoloured = _sharp(client, edit)
    t = header["timings"]
    assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0 and not calls
    _assert_as_integrated(client, recoloured)


def test_steps_give_way_to_the_winners_before_they_are_gathered(client, monkeypatch) -> None:
    """Under a process memory limit (`--memory`), the window managers are asked for room for
    the winners (a float32 value and a step index per voxel; the 32^3 vortex's float32 texture
    is recoloured by the compute pass, so no host output) before the gather allocates them:
    the gather's memory is not left to the next frame's `fit` to find over the limit."""
    from chronocl.core import process_memory
    from chronocl.core.budget import resident_bytes

    events: list[tuple[str, int]] = []
    real_fit = process_memory.ProcessLimit.fit

    def fit(self, extra: int = 0, **kwargs):
        if kwargs.get("caller") is None:  # not a manager's own, making room for its reads
            events.append(("fit", extra))
        return real_fit(self, extra, **kwargs)

    calls = _counting_gather(monkeypatch)
    real_gather = OpenCLEngine.gather

    def gather(self, *args, **kwargs):
        events.append(("gather", 0))
        return real_gather(self, *args, **kwargs)

    monkeypatch.setattr(process_memory.ProcessLimit, "fit", fit)
    monkeypatch.setattr(OpenCLEngine, "gather", gather)
    limit = process_memory.ProcessLimit((resident_bytes() or 0) + (1 << 30))
    with process_memory.limited(limit):
        _open_in(client, "max")
        _until(lambda: calls == ["done"])
    voxels = 32**3  # the vortex store's
    first = events.index(("gather", 0))
    asked = [extra for what, extra in events[:first] if what == "fit"]
    assert asked and asked[-1] >= voxels * (4 + 1), events[: first + 1]


def test_a_window_streamed_under_the_memory_limit_still_recolours_its_tf_edits(tmp_path):
    """A `--memory` that leaves the window's steps no room beside the views' frames: the
    window streams from the store (the frame says why), and max's TF edit still recolours
    with the winners its streamed integration wrote, showing what integrating shows."""
    from chronocl.viewer.server import ViewerServer

    server = ViewerServer(make_stores(tmp_path), memory=TUNING.process_bytes + (1 << 20))
    server.start()
    client = Client(server)
    try:
        fitted, header = _open_in(client, "max")
        assert "the memory limit" in header["timings"]["streamed"], header["timings"]
        edit = {**EDIT, "data_tf": {**EDIT["data_tf"], "value_range": fitted}}
        header, recoloured = _sharp(client, edit)
        t = header["timings"]
        assert t["integrate_ms"] == 0 and t["recolour_ms"] > 0, t
        assert t["streamed"]
        _assert_as_integrated(client, recoloured)
    finally:
        client.close()
        server.stop()


def test_winners_go_with_their_session(rgba8_server, monkeypatch) -> None:
    """A panel's winners belong to its window's session: an edit of the spec and the window at
    once (its window's change lets them go), or another data set of the same shape opened,
    releases them (kept, the data set's held 9-10 bytes a voxel, 1.2 GB at 512^3, until the
    next edit)."""
    import gc

    released: list = []
    real = recolouring.Prepared.release
    monkeypatch.setattr(recolouring.Prepared, "release", lambda p: (released.append(p), real(p)))

    def recoloured(x: float) -> recolouring.Prepared:
        """Recolour an edit (opaque from `x`); the winners it prepared."""
        header, _ = _sharp(client, _opaque_from(x, fitted))
        t = header["timings"]
        assert t["recolour_ms"] > 0 and t["integrate_ms"] == 0, (header["views"], t)
        made = [o for o in gc.get_objects() if type(o) is recolouring.Prepared]  # (no proxy)
        gone = {id(p) for p in released}  # (held in `released`: no id is used again)
        made = [p for p in made if id(p) not in gone and p.t_index() is not None]
        assert len(made) == 1, made
        return made[0]

    client = Client(rgba8_server)
    try:
        fitted, _ = _open_in(client, "max")
        kept = recoloured(0.3)
        header, _ = _sharp(client, {"views": [{"mode": "min"}], "window": {"t0": 2, "t1": 9}})
        assert header["timings"]["integrate_ms"] > 0
        _until(lambda: any(p is kept for p in released))
        _sharp(client, {"views": [{"mode": "max"}], "window": {"t0": 0, "t1": 12}})
        kept = recoloured(0.5)
        client.open(1, size=(96, 96))
        _until(lambda: any(p is kept for p in released))
    finally:
        client.close()
