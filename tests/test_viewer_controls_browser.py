"""The viewer page's orientation and time controls in Chromium: the axes triad follows the
camera, a standard view changes the frame and gives the same frame when pressed again, camera
reset returns the opening frame; play at a set speed (steps/s) and in bounce mode; `?` lists
every key the page binds and Escape closes the list; after the server restarts on the same
port the page reconnects by itself and shows the view it had.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import itertools
import os
import statistics

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from chronocl.viewer.server import ViewerServer

from .test_viewer_page_browser import Page, browser, server, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, full_size_frames  # noqa: F401

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

TRIAD = """() => [...document.querySelectorAll('.view .triad')].map(c => {
  // Coloured pixels of each axis (red x, green y, blue z) in the triad's canvas.
  const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  const n = [0, 0, 0];
  for (let k = 0; k < px.length; k += 4) {
    if (px[k + 3] < 200) continue;
    const [r, g, b] = [px[k], px[k + 1], px[k + 2]];
    if (r > 200 && g < 120 && b < 120) n[0]++;
    else if (g > 180 && r < 120 && b < 120) n[1]++;
    else if (b > 200 && r < 120) n[2]++;
  }
  return {visible: !c.hidden && c.offsetWidth > 0, camera: c.dataset.camera, n};
})"""


def press(p: Page, key: str) -> dict:
    before = p.last()
    p.page.keyboard.press(key)
    return p.settle(before)


def test_standard_views_reset_and_the_axes_triad(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        opening = p.last()["digest"]
        cam0 = p.eval("() => window.viewer.S.state.camera")
        triad = p.eval(TRIAD)
        assert triad[0]["visible"] and all(n > 20 for n in triad[0]["n"])

        # +X: the frame changes; the same view again gives the same frame.
        after_x = press(p, "x")
        assert after_x["digest"] != opening
        cam = p.eval("() => window.viewer.S.state.camera")
        assert (cam["azimuth"], cam["elevation"]) == (-90, 0)
        # Looking along +X, the x axis points away: its arm is foreshortened to (nearly) a dot.
        along_x = p.eval(TRIAD)[0]
        assert along_x["camera"] == "-90,0"
        assert along_x["n"][0] < triad[0]["n"][0] / 2
        # The buttons do what the keys do; back to +X gives +X's frame.
        page.click('#std-views button[data-view="-y"]')
        top = p.settle(after_x)
        assert top["digest"] not in (opening, after_x["digest"])
        page.click('#std-views button[data-view="+x"]')
        again = p.settle(top)
        assert again["digest"] == after_x["digest"]
        press(p, "Shift+Z")  # then orbit and zoom away, and reset
        box = page.locator(".view img").first.bounding_box()
        c = {"x": box["x"] + box["width"] / 2, "y": box["y"] + box["height"] / 2}
        before = p.last()
        page.mouse.move(c["x"], c["y"])
        page.mouse.down()
        page.mouse.move(c["x"] + 120, c["y"] + 50, steps=6)
        page.mouse.up()
        page.mouse.wheel(0, -300)
        p.settle(before)
        page.wait_for_timeout(400)  # the wheel's settle timer
        moved = p.settle({"seq": 0})
        assert moved["digest"] != opening
        reset = press(p, "r")
        assert reset["digest"] == opening
        assert p.eval("() => window.viewer.S.state.camera") == cam0

        # The triad can be hidden (A) and shown again.
        page.keyboard.press("a")
        assert not p.eval(TRIAD)[0]["visible"]
        page.keyboard.press("a")
        assert p.eval(TRIAD)[0]["visible"]
        # Every view has its triad, turned as the camera is.
        before = p.last()
        page.select_option("#nviews", "4")
        p.settle(before)
        press(p, "y")
        triads = p.eval(TRIAD)
        assert len(triads) == 4 and all(t["visible"] and t["camera"] == "0,-89.9" for t in triads)
        assert all(t["n"] == triads[0]["n"] for t in triads)
        press(p, "r")
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-triad-1400x900.png"))
    finally:
        p.close()


def test_play_speed_and_bounce(browser, server):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        T = p.eval("() => window.viewer.S.info.shape.t")
        # A 4-step window, so play runs over several slides before turning.
        before = p.last()
        p.eval(
            """() => { const v = window.viewer; v.S.state.window = {t0: 0, t1: 4, stride: 1}; }"""
        )
        page.keyboard.press("ArrowRight")  # sends the window (1, 5)
        p.settle(before)
        page.select_option("#play-mode", "bounce")

        def run(speed: float, seconds: float) -> list[dict]:
            page.fill("#play-speed", str(speed))
            page.dispatch_event("#play-speed", "change")
            p.eval("() => { window.viewer.playLog.length = 0; }")
            page.click("#play")
            page.wait_for_timeout(seconds * 1000)
            page.click("#play")
            return p.eval("() => window.viewer.playLog")

        slow = run(2, 2.6)
        fast = run(8, 2.6)

        def gap(log: list[dict]) -> float:
            return statistics.median(b["at"] - a["at"] for a, b in itertools.pairwise(log))

        assert len(slow) >= 4 and len(fast) >= 8
        assert 450 <= gap(slow) <= 700, gap(slow)
        assert gap(fast) < 0.6 * gap(slow), (gap(fast), gap(slow))

        # Bounce: the window turns back at the end of the series (and at its start), never
        # jumping from one end to the other as loop does.
        t0s = [e["t0"] for e in slow + fast]
        last = T - 4
        assert last in t0s and 0 in t0s
        assert all(abs(a - b) == 1 for a, b in itertools.pairwise(t0s) if a != b)
        k = t0s.index(last)
        assert t0s[k + 1] == last - 1

        # Loop: from the last window play starts again at 0.
        page.select_option("#play-mode", "loop")
        p.eval("() => { window.viewer.playLog.length = 0; }")
        page.click("#play")
        page.wait_for_function(
            f"() => window.viewer.playLog.some((e, i, l) => i > 0 && l[i-1].t0 === {last}"
            " && e.t0 === 0)",
            timeout=20_000,
        )
        page.click("#play")
    finally:
        p.close()


def test_question_mark_lists_every_shortcut_and_escape_closes_it(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        help_ = page.locator("#help")
        assert not help_.is_visible()
        page.keyboard.press("?")
        assert help_.is_visible()
        table = p.eval("() => window.viewer.shortcuts")
        rows = p.eval(
            """() => [...document.querySelectorAll('#help-keys tr')].map(
                 tr => [tr.dataset.keys, tr.cells[0].innerText, tr.cells[1].innerText])"""
        )
        assert [r[0] for r in rows] == [" ".join(s["keys"]) for s in table]
        assert [(r[1], r[2]) for r in rows] == [(s["label"], s["does"]) for s in table]
        bound = {k for s in table for k in s["keys"]}
        # Every key the page reacts to is in the table (the ones the tests above press too).
        assert {
            " ",
            "ArrowLeft",
            "ArrowRight",
            "r",
            "x",
            "X",
            "y",
            "Y",
            "z",
            "Z",
            "a",
            "b",
        } <= bound
        assert {"+", "-", "?", "Escape"} <= bound
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-shortcuts-1400x900.png"))
        page.keyboard.press("Escape")
        assert not help_.is_visible()
        page.click("#help-toggle")  # the header's ? button opens it too
        assert help_.is_visible()
        page.keyboard.press("?")
        assert not help_.is_visible()
    finally:
        p.close()


def test_page_reconnects_after_a_server_restart(browser, tmp_path, full_size_frames):  # noqa: F811
    from .viewer_helpers import make_stores

    stores = make_stores(tmp_path)
    first = ViewerServer(stores)
    first.start()
    second = None
    p = Page(browser, first, 1400, 900)
    try:
        page = p.page
        page.evaluate("() => { window.notReloaded = true; }")
        before = press(p, "x")  # a view other than the opening one, to be restored
        first.stop()
        page.wait_for_function(
            "() => document.body.dataset.connection === 'retrying'", timeout=20_000
        )
        assert "reconnecting" in page.inner_text("#status")
        dimmed = (
            "() => [getComputedStyle(document.querySelector('.view img')).opacity,"
            " getComputedStyle(document.querySelector('#views'), '::after').content]"
        )
        opacity, note = p.eval(dimmed)
        assert float(opacity) < 0.5 and "stale" in note  # the last picture is not live
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "disconnected.png"))
        frames = p.eval("() => window.viewer.frames")
        second = ViewerServer(stores, port=first.port, token=first.token)
        second.start()
        page.wait_for_function(
            "([n]) => window.viewer.connects === 2 && window.viewer.frames > n",
            arg=[frames],
            timeout=30_000,
        )
        after = p.settle({"seq": 0})
        assert page.evaluate("() => window.notReloaded") is True
        cam = p.eval("() => window.viewer.S.state.camera")
        assert (cam["azimuth"], cam["elevation"]) == (-90, 0)
        assert after["digest"] == before["digest"]  # the same view as before the restart
        opacity, note = p.eval(dimmed)
        assert float(opacity) == 1 and note == "none"
        p.problems.clear()  # the refused reconnects are logged by the browser, not errors
    finally:
        p.close()
        if second is not None:
            second.stop()


def test_the_token_can_come_from_the_environment(monkeypatch, tmp_path):
    """`chronocl view` restarted with the same $CHRONOCL_VIEWER_TOKEN and --port is a server
    an open page reconnects to (a random token would refuse it)."""
    from chronocl.core.errors import InvalidParameterError
    from chronocl.viewer.server import TOKEN_ENV

    monkeypatch.setenv(TOKEN_ENV, "kept-across-restarts")
    srv = ViewerServer(datasets=[])
    try:
        assert srv.token == "kept-across-restarts" and srv.url.endswith("=kept-across-restarts")
    finally:
        srv.sock.close()
        srv.downloads.close()
    given = ViewerServer(datasets=[], token="given-wins-here")
    given.sock.close()
    given.downloads.close()
    assert given.token == "given-wins-here"
    for bad in ("short", "has space in it", "amp&ersand&token"):
        monkeypatch.setenv(TOKEN_ENV, bad)
        with pytest.raises(InvalidParameterError, match=TOKEN_ENV):
            ViewerServer(datasets=[])


HIST_BARS = """() => { // histogram-coloured pixels in the TF canvas: bars drawn log or linear
  const c = document.getElementById('tf');
  const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let n = 0;
  for (let k = 0; k < px.length; k += 4) if (px[k + 3] > 60 && px[k + 2] > px[k] + 40) n++;
  return n;
}"""


def test_tf_editor_window_histogram_colormap_typed_values_and_hover(browser, server, tmp_path):  # noqa: F811
    from chronocl.core.tf import DataTF

    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        hist = "() => window.viewer.S.histogram && window.viewer.S.histogram.steps"
        page.wait_for_function(hist, timeout=60_000)
        # The histogram counts the window's steps, and follows the window when it moves.
        before = p.last()
        p.eval("() => { window.viewer.S.state.window = {t0: 0, t1: 4, stride: 1}; }")
        page.keyboard.press("ArrowRight")  # sends the window (1, 5)
        p.settle(before)
        page.wait_for_function(f"() => ({hist})().join() === '1,2,3,4'", timeout=60_000)
        assert "histogram of the 4 steps of window 1:5;" in page.inner_text("#hist-note")
        # A long window is counted from some of its steps: the note says which, of how many.
        before = p.last()
        p.eval("() => { window.viewer.S.state.window = {t0: 0, t1: 10, stride: 1}; }")
        page.keyboard.press("ArrowRight")  # sends the window (1, 11)
        p.settle(before)
        page.wait_for_function(f"() => ({hist})().join() === '2,4,6,8,10'", timeout=60_000)
        note = page.inner_text("#hist-note")
        assert "histogram of 5 of the 10 steps of window 1:11 (2, 4, 6, 8, 10);" in note, note
        before = p.last()
        p.eval("() => { window.viewer.S.state.window = {t0: 2, t1: 6, stride: 1}; }")
        page.keyboard.press("ArrowLeft")  # back to the window (1, 5)
        p.settle(before)
        page.wait_for_function(f"() => ({hist})().join() === '1,2,3,4'", timeout=60_000)
        logged = p.eval(HIST_BARS)
        page.uncheck("#hist-log")
        assert 0 < p.eval(HIST_BARS) < logged  # linear counts: the rare values' bars shrink
        # A colour map recolours the points as DataTF.with_colormap does, opacity kept.
        points = p.eval("() => window.viewer.S.state.data_tf.points")
        before = p.last()
        page.select_option("#tf-colormap", "viridis")
        after = p.settle(before)
        got = p.eval("() => window.viewer.S.state.data_tf.points")
        want = DataTF(points=[tuple(q) for q in points]).with_colormap("viridis").points
        assert len(got) == len(want)
        for g, w in zip(got, want, strict=True):
            assert g == pytest.approx(list(w), abs=1e-9)
        assert after["digest"] != before["digest"]
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "tf-viridis.png"))
        # The selected point's value and opacity typed in (under the map, of a handle: the
        # curve's own points; the last one keeps its place at the end of the range).
        handles = p.eval("() => window.viewer.tfHandles()")
        at = p.eval(f"() => window.viewer.tfPointAt({handles[-1]})")
        page.mouse.click(at["x"], at["y"])
        # Values are the TF's: over its fitted range (a data set opens fitted to its window).
        lo, hi = p.eval("() => window.viewer.S.state.data_tf.value_range")
        before = p.last()
        page.fill("#point-alpha", "0.25")
        page.dispatch_event("#point-alpha", "change")
        p.settle(before)
        last = p.eval("() => window.viewer.S.state.data_tf.points.at(-1)")
        assert last[4] == 0.25 and last[0] == 1.0
        at = p.eval(f"() => window.viewer.tfPointAt({handles[-2]})")
        page.mouse.click(at["x"], at["y"])
        mid = lo + 0.7 * (hi - lo)
        page.fill("#point-value", str(mid))
        page.dispatch_event("#point-value", "change")
        typed = p.eval("() => window.viewer.S.state.data_tf.points[window.viewer.S.selectedPoint]")
        assert typed[0] == pytest.approx(0.7, abs=1e-9)
        # A dragged point's value and opacity fields, and the readout, follow it as it moves.
        at = p.eval(f"() => window.viewer.tfPointAt({handles[1]})")
        page.mouse.move(at["x"], at["y"])
        page.mouse.down()
        page.mouse.move(at["x"] + 25, at["y"] - 30, steps=5)
        moved = p.eval("() => window.viewer.S.state.data_tf.points[window.viewer.S.selectedPoint]")
        fields = p.eval(
            "() => [document.querySelector('#point-value').value,"
            " document.querySelector('#point-alpha').value]"
        )
        page.mouse.up()
        value = lo + moved[0] * (hi - lo)
        assert float(fields[0]) == pytest.approx(value, rel=2e-3)
        assert float(fields[1]) == pytest.approx(moved[4], abs=2e-3) and moved[4] > 0.05
        assert f"value {fields[0]} · opacity {fields[1]}" in page.inner_text("#tf-hover")
        # The readout under the pointer: value, opacity and the histogram's count there.
        box = page.locator("#tf").bounding_box()
        page.mouse.move(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.5)
        text = page.inner_text("#tf-hover")
        assert text.startswith("value ") and "opacity" in text and "sampled voxels" in text
    finally:
        p.close()


OUTLINE = "() => document.querySelector('.clip-outline polygon').getAttribute('points') || ''"


def test_clip_plane_outline_and_turning_it_by_dragging(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        page.click("summary:has-text('Slicing plane')")
        before = p.last()
        page.check("#clip-on")
        p.settle(before)
        square = p.eval(OUTLINE)
        assert len(square.split()) == 4  # the plane x = 0 cuts the box in a rectangle
        # With "drag turns the plane" a drag turns the normal, not the camera.
        page.check("#clip-drag")
        camera = p.eval("() => window.viewer.S.state.camera")
        box = page.locator(".view img").first.bounding_box()
        cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
        before = p.last()
        page.mouse.move(cx, cy)
        page.mouse.down()
        page.mouse.move(cx + 50, cy + 30, steps=5)
        page.mouse.up()
        after = p.settle(before)
        normal = p.eval("() => window.viewer.S.state.clip.normal")
        assert p.eval("() => window.viewer.S.state.camera") == camera
        assert abs(normal[0]) < 0.99 and abs(sum(c * c for c in normal) - 1) < 1e-6
        assert page.input_value("#clip-axis") == "custom"
        assert after["digest"] != before["digest"] and p.eval(OUTLINE) != square
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "clip-turned.png"))
    finally:
        p.close()


def entered(page, field) -> None:
    """Enter pressed in `field`, and the update it makes sent: the page sends it on the next
    animation frame, and until then a settled frame answering the update before (the resize's)
    would pass for its answer."""
    sent = page.evaluate("() => window.viewer.sent")
    field.press("Enter")
    page.wait_for_function("(s) => window.viewer.sent > s", arg=sent)


def test_two_periods_side_by_side(browser, server, tmp_path):  # noqa: F811
    """Typing a window into a view's header gives that view its own period; emptying it links
    the view to the timeline's window again."""
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        before = p.last()
        page.select_option("#nviews", "2")
        p.settle(before)
        labels = "() => [...document.querySelectorAll('.view-label')].map(l => l.textContent)"
        own = page.locator(".own-window").nth(1)
        before = p.last()
        own.fill("0:4")
        # a relayout while the window is half typed (here a resize; in CI a legend appearing
        # after the two views' frame) leaves what is typed, and Enter sends it
        page.set_viewport_size({"width": 1380, "height": 900})
        page.wait_for_timeout(400)
        entered(page, own)
        p.settle(before)
        first, second = p.eval(labels)
        assert second.endswith("steps 0:4") and not first.endswith("steps 0:4")
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "two-periods.png"))
        before = p.last()
        own.fill("")
        entered(page, own)
        p.settle(before)
        first, second = p.eval(labels)
        assert first.split("steps")[1] == second.split("steps")[1]  # linked again
        own.fill("9:99")
        own.press("Enter")
        assert "bad" in own.get_attribute("class")  # beyond the series: refused in the page
    finally:
        p.close()


def test_movie_of_an_orbit_downloads(browser, server, tmp_path):  # noqa: F811
    """Save movie renders an orbit with a frame count as it goes, then downloads the video."""
    import imageio.v3 as iio

    p = Page(browser, server, 1024, 640)
    try:
        page = p.page
        page.click("summary:has-text('Movie')")
        page.select_option("#movie-format", "gif")
        page.fill("#movie-frames", "3")
        with page.expect_download(timeout=120_000) as got:
            page.click("#save-movie")
        assert got.value.suggested_filename.startswith("vortex-orbit-")
        frames = iio.imread(got.value.path(), index=None, extension=".gif")
        assert frames.shape[0] == 3 and not (frames[0] == frames[1]).all()
        assert page.inner_text("#movie-progress") == "frame 3 of 3"
        assert page.is_enabled("#save-movie")
    finally:
        p.close()


def test_saved_png_is_laid_out_as_the_screen(browser, server, tmp_path):  # noqa: F811
    """Save PNG with four views writes the 2 x 2 grid the page shows, not a 1 x 4 strip, each
    panel over its own legend."""
    import numpy as np
    from PIL import Image

    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        before = p.last()
        page.select_option("#nviews", "4")
        p.settle(before)
        columns = p.eval("() => window.viewer.S.columns")
        tops = p.eval(
            "() => [...document.querySelectorAll('#views .view')]"
            ".map(v => Math.round(v.getBoundingClientRect().top))"
        )
        assert columns == 2 and len(set(tops)) == 2  # two rows of two on screen
        w, h = p.eval("() => window.viewer.S.state.size")
        with page.expect_download(timeout=120_000) as got:
            page.click("#save-image")
        got.value.save_as(os.path.join(shots_dir(tmp_path), "saved-4-views.png"))
        image = np.asarray(Image.open(got.value.path()).convert("RGB"))
        assert image.shape[1] == 2 * w and image.shape[0] > 2 * h  # 2 x 2, captions, legends
        assert image.shape[0] < 4 * h
    finally:
        p.close()
