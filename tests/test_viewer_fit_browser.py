"""Fit to window in Chromium, on a plume whose first steps are faint (step 0 peaks at about a
twelfth of the run's maximum): the first picture is fitted as `chronocl render` fits it and
shows the early steps (blue under the rgb time colours) that the series' range hides; the Fit
button and the F key give the curve the selected view's fitted range, its handles move on the
editor's axis and the fields follow, undo takes it back; a mode change fits the default curve
again in the same edit, never a curve edited by hand; "series range" keeps the picture. A mode
change goes at once and its (slow) fit follows with the data TF alone: an edit made before
the reply holds, and a reconnect before it keeps the mode, reopens unfitted and fits again.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os
import threading
import time

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from chronocl.core.tf import DEFAULT_DATA_POINTS

from .test_viewer_page_browser import Page, browser, shots_dir  # noqa: F401
from .viewer_helpers import (  # noqa: F401
    CHROMIUM,
    fitted,
    full_size_frames,
    plume_store,
    serving,
)

pytestmark = [
    pytest.mark.skipif(
        not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
    ),
    pytest.mark.usefixtures("full_size_frames"),
]

FIT_DELAY_S = 2.0
# The page's state and each panel's caption (the frame's label: the server's state).
SHOWN = """() => {
  const S = window.viewer.S;
  return {
    modes: S.state.views.map((v) => v.mode),
    orders: S.state.views.map((v) => v.order || 'forward'),
    range: S.state.data_tf.value_range || null,
    fits: S.fits.length,
    undo: window.viewer.history.undo,
    labels: [...document.querySelectorAll('.view .view-label')].map((l) => l.title),
  };
}"""
# The first view's picture: pixels that show something, and bluish ones (the early steps under
# the rgb time colours, old blue -> new red).
PIXELS = """async () => {
  const img = document.querySelector('.view img');
  // a newer frame may replace the picture mid-decode (EncodingError): decode that one
  for (let k = 0; ; k++) {
    try { await img.decode(); break; } catch (e) { if (k > 20) throw e; }
    await new Promise((r) => setTimeout(r, 50));
  }
  const c = document.createElement('canvas');
  c.width = img.naturalWidth;
  c.height = img.naturalHeight;
  const ctx = c.getContext('2d');
  ctx.drawImage(img, 0, 0);
  const px = ctx.getImageData(0, 0, c.width, c.height).data;
  let lit = 0, blue = 0;
  for (let k = 0; k < px.length; k += 4) {
    const [r, g, b] = [px[k], px[k + 1], px[k + 2]];
    if (Math.max(r, g, b) > 40) lit += 1;
    if (b > 60 && b > r + 30) blue += 1;
  }
  return {lit, blue, n: c.width * c.height};
}"""
# Where the editor draws each handle (page px), and what the fields and the range line say.
EDITOR = """() => {
  const v = window.viewer, $ = (id) => document.getElementById(id);
  return {
    at: v.tfHandles().map((i) => v.tfPointAt(i)),
    range: v.S.state.data_tf.value_range || null,
    point: v.S.state.data_tf.points[v.S.selectedPoint],
    value: Number($('point-value').value),
    alpha: Number($('point-alpha').value),
    note: $('tf-range').textContent,
  };
}"""
# The time TF's fields `t` changed, as the page sends them.
TIME_TF = """async (t) => {
  const m = await import(new URL('static/connection.js', location.href).href);
  m.update({time_tf: Object.assign({}, window.viewer.S.state.time_tf, t)}, 'full');
}"""
# An update as the page sends it (the page's own module), for what no control does at once.
UPDATE = """async (fields) => {
  const m = await import(new URL('static/connection.js', location.href).href);
  m.update(fields, 'full');
}"""


@pytest.fixture(scope="module")
def plume(tmp_path_factory):
    return plume_store(tmp_path_factory, "viewer-fit-browser")


@pytest.fixture(scope="module")
def server(plume):
    yield from serving([plume])


@pytest.fixture
def slow_fits(monkeypatch):
    """Fits answered `delay[0]` seconds late (as where the window's sample takes long to
    read), so that the page goes on before the reply comes; yields `delay`. The test ends once
    no fit is under way (a stopped server's client thread is done before the next test)."""
    from chronocl.viewer import tasks

    real = tasks.fit_reply
    delay = [FIT_DELAY_S]
    running = []  # one entry per fit under way
    lock = threading.Lock()

    def slow(*args):
        with lock:
            running.append(1)
        try:
            time.sleep(delay[0])
            return real(*args)
        finally:
            with lock:
                running.pop()

    monkeypatch.setattr(tasks, "fit_reply", slow)
    yield delay
    deadline = time.monotonic() + 30
    while running and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.2)  # the thread's last step after its reply: its views released


def act(p: Page, do) -> dict:
    """Do something that sends an update; the settled frame answering it."""
    before = p.last()
    do()
    return p.settle(before)


def test_first_picture_fit_button_undo_and_mode_change(browser, server, plume, tmp_path):  # noqa: F811
    shots = shots_dir(tmp_path)
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        # The first picture: the whole run (10 steps), the default curve over the fitted range.
        assert p.eval("() => window.viewer.S.state.window") == {"t0": 0, "t1": 10, "stride": 1}
        first = p.eval(EDITOR)
        assert first["range"] == pytest.approx(fitted(plume, 0, 10, "alpha"), rel=1e-12)
        assert "fitted to alpha, window 0:10" in first["note"]
        page.screenshot(path=os.path.join(shots, "fit-first-picture.png"))
        # Step 0 alone (the time opacity a hat on it), under the first picture's data TF: the
        # faint first step's plume shows (blue, the oldest time colour) ...
        hat = {"alpha": "hat", "center": 0.0, "width": 0.2, "floor": 0.0, "value": 1.0}
        act(p, lambda: p.eval(TIME_TF, hat))
        step0 = p.eval(PIXELS)
        page.screenshot(path=os.path.join(shots, "fit-first-picture-step0.png"))
        # ... where the same curve over the series' range (the viewer's picture before it
        # fitted) hides it.
        default = [list(q) for q in DEFAULT_DATA_POINTS]
        act(p, lambda: p.eval(UPDATE, {"data_tf": {"points": default}}))
        hidden = p.eval(PIXELS)
        page.screenshot(path=os.path.join(shots, "fit-series-range-step0.png"))
        # (a small, dim blob at the source: 8 % of the run's maximum, under a range fitted to
        # the whole window; where the series' range leaves not one pixel)
        assert step0["blue"] > 200 and step0["blue"] > 0.3 * step0["lit"], step0
        assert hidden["lit"] < 0.1 * step0["lit"], (step0, hidden)
        for _ in range(2):  # back to the first picture
            act(p, lambda: page.keyboard.press("Control+z"))
        assert p.eval(EDITOR)["range"] == first["range"]
        assert p.eval("() => window.viewer.S.state.time_tf.alpha") == "constant"

        # Window 0:2, the faint steps alone: the range stays the first window's until fitted.
        p.eval("() => { window.viewer.S.state.window = {t0: 1, t1: 3, stride: 1}; }")
        act(p, lambda: page.keyboard.press("ArrowLeft"))
        assert p.eval("() => window.viewer.S.state.window")["t0"] == 0
        before = p.eval(EDITOR)
        assert before["range"] == first["range"]
        dim = p.eval(PIXELS)
        act(p, lambda: page.click("#tf-fit"))
        after = p.eval(EDITOR)
        assert after["range"] == pytest.approx(fitted(plume, 0, 2, "alpha"), rel=1e-12)
        assert "fitted to alpha, window 0:2" in after["note"]
        # The curve keeps its shape (points, opacities) and moves on the axis: the fitted range
        # of the faint steps lies lower, so every handle but the first moves left.
        assert after["point"] == before["point"]
        assert all(
            a["y"] == pytest.approx(b["y"], abs=0.5)
            for a, b in zip(after["at"], before["at"], strict=True)
        )
        assert all(
            a["x"] < b["x"] - 5 for a, b in zip(after["at"][1:], before["at"][1:], strict=True)
        )
        # The fields follow: the selected point's value is now on the fitted range.
        lo, hi = after["range"]
        assert after["value"] == pytest.approx(lo + after["point"][0] * (hi - lo), rel=2e-3)
        assert after["alpha"] == pytest.approx(after["point"][4], abs=1e-3)
        bright = p.eval(PIXELS)
        assert bright["lit"] > 1.5 * dim["lit"], (dim, bright)
        page.screenshot(path=os.path.join(shots, "fit-window-0-2.png"))
        page.locator("#tf").screenshot(path=os.path.join(shots, "fit-editor-0-2.png"))
        # Pressed again: nothing changes (a fitted curve is not squeezed again), no new edit.
        undo = p.eval("() => window.viewer.history.undo")
        page.click("#tf-fit")
        page.wait_for_timeout(500)
        assert p.eval(EDITOR)["at"] == after["at"]
        assert p.eval("() => window.viewer.history.undo") == undo

        # Undo and redo, as any TF edit.
        act(p, lambda: page.keyboard.press("Control+z"))
        assert p.eval(EDITOR)["range"] == before["range"] and p.eval(EDITOR)["at"] == before["at"]
        assert "fitted to alpha, window 0:10" in p.eval(EDITOR)["note"]
        act(p, lambda: page.keyboard.press("Control+Shift+Z"))
        assert p.eval(EDITOR)["at"] == after["at"]

        # A mode change with the default curve: fitted again to the new mode, in the same edit
        # (the mode's frame comes first, the fit's after it).
        undo = p.eval("() => window.viewer.history.undo")
        fits, shown = p.eval("() => window.viewer.S.fits.length"), p.last()
        page.select_option(".view .mode", "max")
        fit_arrived(p, fits, shown)
        assert p.eval(EDITOR)["range"] == pytest.approx(fitted(plume, 0, 2, "max"), rel=1e-12)
        assert p.eval("() => window.viewer.history.undo") == undo + 1
        act(p, lambda: page.keyboard.press("Control+z"))
        assert p.eval("() => window.viewer.S.state.views[0].mode") == "alpha"
        assert p.eval(EDITOR)["range"] == after["range"]

        # A curve edited by hand is not fitted again on a mode change; the F key fits it.
        h = p.eval("() => window.viewer.tfHandles()")[2]
        at = p.eval(f"() => window.viewer.tfPointAt({h})")

        def drag():
            page.mouse.move(at["x"], at["y"])
            page.mouse.down()
            page.mouse.move(at["x"] + 10, at["y"] - 30, steps=4)
            page.mouse.up()

        act(p, drag)
        edited = p.eval(EDITOR)
        assert edited["range"] == after["range"]
        act(p, lambda: page.select_option(".view .mode", "min"))
        assert p.eval(EDITOR)["range"] == after["range"]
        act(p, lambda: page.keyboard.press("f"))
        assert p.eval(EDITOR)["range"] == pytest.approx(fitted(plume, 0, 2, "min"), rel=1e-12)
        assert p.eval(EDITOR)["point"] == edited["point"]

        # "series range": the curve spread over the series' range where it was drawn; the
        # picture stays (up to the TF's sampling).
        act(p, lambda: page.select_option(".view .mode", "alpha"))
        act(p, lambda: page.keyboard.press("f"))
        fit_shot = p.eval(PIXELS)
        fit_at = p.eval(EDITOR)["at"]
        act(p, lambda: page.click("#tf-unfit"))
        spread = p.eval(EDITOR)
        assert spread["range"] is None and "series' range" in spread["note"]
        for a in fit_at:  # each handle still where it was (two flat ends added)
            assert min(abs(a["x"] - b["x"]) + abs(a["y"] - b["y"]) for b in spread["at"]) < 1.0
        same = p.eval(PIXELS)
        assert abs(same["lit"] - fit_shot["lit"]) < 0.03 * fit_shot["lit"]
        page.locator("#tf").screenshot(path=os.path.join(shots, "fit-editor-spread.png"))
    finally:
        p.close()


def fit_arrived(p: Page, fits: int, before: dict) -> dict:
    """Wait for the fit after `fits` fits and the frame answering it; what the page shows."""
    p.page.wait_for_function("([n]) => window.viewer.S.fits.length > n", arg=[fits], timeout=30_000)
    p.eval("() => new Promise((r) => requestAnimationFrame(() => r()))")  # its update sent
    p.settle(before)
    return p.eval(SHOWN)


def test_a_mode_change_and_an_edit_before_its_fit_both_hold(
    browser,  # noqa: F811
    server,
    plume,
    slow_fits,
    tmp_path,
):
    """The first view's mode goes at once; another view edited before the (slow) fit's reply
    keeps its edit, the reply gives the data TF alone; undo takes back the fit, the edit and
    the mode one by one. With no edit between, the refit is in the mode change's undo step."""
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        act(p, lambda: page.select_option("#nviews", "2"))
        start = p.eval(SHOWN)
        assert start["modes"][0] == "alpha" and start["orders"] == ["forward", "forward"]
        assert start["range"] == pytest.approx(fitted(plume, 0, 10, "alpha"), rel=1e-12)
        before = p.last()
        page.locator(".view .mode").nth(0).select_option("max")
        page.locator(".view .order").nth(1).click()
        now = p.eval(SHOWN)  # before the fit's reply: the mode is the page's state already
        assert now["modes"][0] == "max" and now["orders"][1] == "backward"
        assert now["range"] == start["range"] and now["fits"] == start["fits"]
        got = fit_arrived(p, start["fits"], before)
        assert got["range"] == pytest.approx(fitted(plume, 0, 10, "max"), rel=1e-12)
        assert got["modes"] == ["max", start["modes"][1]]
        assert got["orders"] == ["forward", "backward"]
        # The server draws both edits (each caption starts with its view's mode and order).
        assert got["labels"][0].startswith("max, forward, ")
        assert got["labels"][1].startswith(f"{start['modes'][1]}, backward, ")
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "fit-mode-change-and-edit.png"))
        # Three steps (the fit came after the other edit): undone one by one.
        assert got["undo"] == start["undo"] + 3
        act(p, lambda: page.keyboard.press("Control+z"))
        back = p.eval(SHOWN)
        assert back["range"] == start["range"] and back["modes"][0] == "max"
        assert back["orders"][1] == "backward"
        act(p, lambda: page.keyboard.press("Control+z"))
        assert p.eval(SHOWN)["orders"][1] == "forward"
        act(p, lambda: page.keyboard.press("Control+z"))
        back = p.eval(SHOWN)
        assert back["modes"] == start["modes"] and back["range"] == start["range"]
        assert back["labels"][0].startswith("alpha, forward, ")

        # Nothing edited before the reply: the mode and its fit are one step.
        before = p.last()
        page.locator(".view .mode").nth(0).select_option("min")
        got = fit_arrived(p, back["fits"], before)
        assert got["range"] == pytest.approx(fitted(plume, 0, 10, "min"), rel=1e-12)
        assert got["undo"] == start["undo"] + 1
        act(p, lambda: page.keyboard.press("Control+z"))
        back = p.eval(SHOWN)
        assert back["modes"] == start["modes"] and back["range"] == start["range"]
    finally:
        p.close()


def test_a_mode_change_outlives_a_reconnect_before_its_fit(
    browser,  # noqa: F811
    plume,
    slow_fits,
    monkeypatch,
):
    """The server stops before the refit of a mode change answers: the page comes back with
    the mode, reopens its data set without fitting it there (the page sends its own state
    back), and asks for the lost refit again, in the mode change's undo step."""
    from chronocl.viewer import worker
    from chronocl.viewer.server import ViewerServer

    real = worker.fitted_default
    opened = []
    monkeypatch.setattr(worker, "fitted_default", lambda *a: opened.append(1) or real(*a))
    slow_fits[0] = 5.0  # long after the socket closed
    first = ViewerServer([plume])
    first.start()
    second = None
    p = Page(browser, first, 1400, 900)
    try:
        page = p.page
        start = p.eval(SHOWN)
        assert opened == [1]
        sent = p.eval("() => window.viewer.sent")
        page.locator(".view .mode").nth(0).select_option("max")
        page.wait_for_function(  # the mode's frame: the fit asked after it is under way
            "([n]) => window.viewer.sent > n && window.viewer.last.id >= window.viewer.sent",
            arg=[sent],
            timeout=30_000,
        )
        assert p.eval(SHOWN)["fits"] == start["fits"]
        first.stop()
        page.wait_for_function(
            "() => document.body.dataset.connection === 'retrying'", timeout=20_000
        )
        slow_fits[0] = FIT_DELAY_S
        second = ViewerServer([plume], port=first.port, token=first.token)
        second.start()
        page.wait_for_function(
            "() => window.viewer.connects === 2 && window.viewer.S.fits.length > 1",
            timeout=30_000,
        )
        p.settle({"seq": 0})
        got = p.eval(SHOWN)
        assert opened == [1]  # the reopen for the restore was not fitted
        assert got["modes"][0] == "max" and got["labels"][0].startswith("max, ")
        assert got["range"] == pytest.approx(fitted(plume, 0, 10, "max"), rel=1e-12)
        assert got["undo"] == start["undo"] + 1
        p.problems.clear()  # the refused reconnects are logged by the browser, not errors
    finally:
        p.close()
        first.stop()
        if second is not None:
            second.stop()
