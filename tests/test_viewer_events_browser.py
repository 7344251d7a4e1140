"""The events panel in Chromium, as a user drives it: Find events lists the window's events of
a series with a merge, a birth and a death known by construction; the window slid away, a
click on the merge moves the window back to it and frames it (the camera's focus about its
centroid); the markers are drawn in the view's picture and go when unchecked; the tracks list
and its size and value plots. Screenshots of the panel and of a frame with markers go to
$CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import importlib.util
import os
import time

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")
pytest.importorskip("cc3d")

from chronocl.data.series import TimeSeries
from chronocl.events import extra
from chronocl.render.markers import MARKER_RGB, PATH_RGB

from .test_viewer_events import merging_blobs
from .test_viewer_page_browser import Page, browser, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, full_size_frames, serving  # noqa: F401

pytestmark = [
    pytest.mark.skipif(
        not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
    ),
    pytest.mark.usefixtures("full_size_frames"),  # pictures compared are the same size
]

STEPS, MERGE = 20, 6  # the default window of 20 steps is 5:15


def series():
    """Two blobs merging between steps 6 and 7; a third born at step 10, gone after 13."""
    a = merging_blobs(STEPS, MERGE)
    a[10:14, 2:6, 11:15, 24:28] = 1.0
    return a


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer-events-page") / "blobs.zarr"
    TimeSeries.from_array(series(), source="blobs").save(path)
    yield from serving([path])


# The pixels of colour `rgb` (within 40 a channel) in the first view's picture, decoded first:
# all of it, or (`r` given) the square within `r` pixels either way of its middle.
COLOURED = """async ([rgb, r]) => {
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
  const [x0, y0, w, h] = r === null ? [0, 0, c.width, c.height]
    : [Math.round(c.width / 2 - r), Math.round(c.height / 2 - r), 2 * r, 2 * r];
  const px = ctx.getImageData(x0, y0, w, h).data;
  let n = 0;
  for (let k = 0; k < px.length; k += 4) {
    const d = Math.max(...[0, 1, 2].map((i) => Math.abs(px[k + i] - rgb[i])));
    if (d < 40) n++;
  }
  return n;
}"""


def coloured(p, rgb, middle: int | None = None) -> int:
    """The pixels of colour `rgb` in the first view's picture (`middle`: within that many pixels
    of its middle)."""
    return p.eval(COLOURED, [list(rgb), middle])


# Non-background pixels of a canvas (a plot drawn).
INKED = """(id) => {
  const c = document.getElementById(id);
  const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let n = 0;
  for (let k = 0; k < px.length; k += 4) if (px[k + 3] > 0) n++;
  return n;
}"""


def test_find_events_list_click_a_merge_and_see_its_markers(browser, server, tmp_path):  # noqa: F811
    shots = os.environ.get("CHRONOCL_SCREENSHOTS") or shots_dir(tmp_path)
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        assert p.eval("() => window.viewer.S.state.window") == {"t0": 5, "t1": 15, "stride": 1}
        plain = coloured(p, MARKER_RGB)
        before = p.last()
        page.click("#events-find")
        page.wait_for_function("() => window.viewer.events && window.viewer.events.found")
        found = p.eval("() => window.viewer.events.found")
        assert found["window"] == [5, 15, 1]
        kinds = [(e["kind"], e["step"], e["next_step"]) for e in found["events"]]
        assert kinds == [("merge", 6, 7), ("birth", 9, 10), ("death", 13, 14)]
        rows = page.locator("#events-list li[data-index]")
        assert rows.count() == 3
        assert rows.nth(0).inner_text().split("\n")[0].endswith("merge")
        assert "6→7" in rows.nth(0).inner_text() and "192" in rows.nth(0).inner_text()
        # The markers (checked by default) are drawn once found: a frame with yellow rings.
        marked = p.settle(before)
        assert coloured(p, MARKER_RGB) > plain + 30
        # The longest track is plotted: its size and value curves are drawn.
        assert p.eval("() => window.viewer.events.track") == found["tracks"][0]["id"]
        assert p.eval(INKED, "events-size") > 200 and p.eval(INKED, "events-value") > 200
        assert page.locator("#events-tracks li").count() == found["tracks_total"] == 3
        page.locator("#events-panel").screenshot(path=os.path.join(shots, "events-panel.png"))

        # Slide the window away from the merge (the arrow keys), then click the merge.
        page.evaluate("() => document.activeElement && document.activeElement.blur()")
        for _ in range(3):
            before = p.last()
            page.keyboard.press("ArrowRight")
            p.settle(before)
        assert p.eval("() => window.viewer.S.state.window") == {"t0": 8, "t1": 18, "stride": 1}
        before = p.last()
        rows.nth(0).click()
        moved = p.settle(before)
        assert moved["digest"] != marked["digest"]
        window = p.eval("() => window.viewer.S.state.window")
        assert window == {"t0": 2, "t1": 12, "stride": 1}  # the merge's steps in its middle
        # The camera frames the merge: the frame's focus is the event's box, about its centroid.
        focus = p.eval("() => window.viewer.S.focus")
        assert focus == pytest.approx(found["events"][0]["focus"], abs=1e-6)
        assert "selected" in rows.nth(0).get_attribute("class")
        with_markers = coloured(p, MARKER_RGB)
        assert with_markers > 30
        page.locator(".view").first.screenshot(path=os.path.join(shots, "events-frame.png"))
        page.screenshot(path=os.path.join(shots, "events-page.png"))

        # The camera turns about the merge's centroid: its ring is at the picture's middle. The
        # birth (off the middle of the volume), clicked: its steps are in the window, which
        # stays; its ring comes to the middle.
        assert coloured(p, MARKER_RGB, 16) > 15
        before = p.last()
        rows.nth(1).click()
        p.settle(before)
        assert p.eval("() => window.viewer.S.state.window") == window
        assert p.eval("() => window.viewer.S.focus") == pytest.approx(found["events"][1]["focus"])
        assert coloured(p, MARKER_RGB, 16) > 15
        page.locator(".view").first.screenshot(path=os.path.join(shots, "events-birth.png"))
        # A click on the born blob (the middle of the picture now) picks its track.
        page.click(f'#events-tracks li[data-track="{found["tracks"][0]["id"]}"]')
        born = next(t for t in found["tracks"] if t["start"] == 10)
        box = page.locator(".view img").first.bounding_box()
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.wait_for_function(f"() => window.viewer.events.track === {born['id']}")
        assert page.inner_text("#events-track-text").startswith("picked in the view (step 13)")
        before = p.last()
        rows.nth(0).click()
        p.settle(before)

        # Markers unchecked: the same view without them. Waited for by their pixels: a frame
        # of the click before (its refine) may come after `before`, and the redraw answers the
        # newest update's id, not the events message's, so no one frame marks the change.
        def yellow_until(holds, what: str) -> None:
            end = time.monotonic() + 30
            while not holds(count := coloured(p, MARKER_RGB)):
                assert time.monotonic() < end, f"{what}: {count} yellow pixels"
                time.sleep(0.1)

        page.uncheck("#events-markers")
        yellow_until(lambda n: n < with_markers / 3, "markers still drawn")
        page.check("#events-markers")
        yellow_until(lambda n: n > with_markers * 0.8, "markers not drawn again")

        # The merge's track is highlighted since the click: a path through its centroids.
        assert p.eval("() => window.viewer.events.highlighted") == found["events"][0]["tracks"][0]
        assert coloured(p, PATH_RGB) > 30

        # A track chosen in the list is plotted and highlighted (the blob born at step 10).
        born = next(t for t in found["tracks"] if t["start"] == 10)
        drawn = int(page.get_attribute("#events-size", "data-drawn"))
        page.click(f'#events-tracks li[data-track="{born["id"]}"]')
        # Waited for by what it draws, not by one frame: the redraw answers the newest update's
        # id, so a frame of the click before may stand in for it (failed once in CI, 3.11)
        page.wait_for_function(
            "(n) => +document.getElementById('events-size').dataset.drawn === n", arg=drawn + 1
        )
        assert p.eval("() => window.viewer.events.track") == born["id"]
        text = page.inner_text("#events-track-text")
        assert text.startswith(f"track {born['id']}: steps 10–13")
        deadline = time.monotonic() + 60
        while coloured(p, PATH_RGB) <= 15 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert coloured(p, PATH_RGB) > 15
        page.screenshot(path=os.path.join(shots, "events-track.png"))
    finally:
        p.close()


def test_without_the_events_extra_the_panel_says_how_to_install_it(
    browser,  # noqa: F811
    server,
    monkeypatch,
    tmp_path,
):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "cc3d" else real(name, *a)
    )

    def missing(module):
        raise extra.MissingExtraError(f"feature tracking needs {module}; {extra.INSTALL}")

    monkeypatch.setattr(extra, "require", missing)
    p = Page(browser, server, 1400, 900)  # (it waits for the first frame)
    try:
        page = p.page
        assert page.is_disabled("#events-find")
        shots = os.environ.get("CHRONOCL_SCREENSHOTS") or shots_dir(tmp_path)
        page.locator("#events-panel").screenshot(path=os.path.join(shots, "events-missing.png"))
        assert page.inner_text("#events-text") == (
            "feature tracking is not installed: pip install 'chronocl[events]'"
        )
        # The rest of the viewer works: a standard view gives a new frame.
        before = p.last()
        page.click('#std-views button[data-view="+x"]')
        assert p.settle(before)["digest"] != before["digest"]
    finally:
        p.close()


def test_space_on_a_focused_row_chooses_it_and_does_not_play(browser, server):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        page.click("#events-find")
        page.wait_for_function("() => window.viewer.events && window.viewer.events.found")
        found = p.eval("() => window.viewer.events.found")
        born = next(t for t in found["tracks"] if t["start"] == 10)
        page.focus(f'#events-tracks li[data-track="{born["id"]}"]')
        page.keyboard.press(" ")
        page.wait_for_function(f"() => window.viewer.events.highlighted === {born['id']}")
        assert p.eval("() => !!window.viewer.S.playing") is False
        page.focus("#events-list li[data-index='0']")
        page.keyboard.press("Enter")
        page.wait_for_function("() => window.viewer.events.event === 0")
        page.focus("#events-list li[data-index='1']")
        page.keyboard.press(" ")
        page.wait_for_function("() => window.viewer.events.event === 1")
        assert p.eval("() => !!window.viewer.S.playing") is False
        # Space elsewhere still plays and pauses.
        page.evaluate("() => document.activeElement && document.activeElement.blur()")
        page.keyboard.press(" ")
        assert p.eval("() => !!window.viewer.S.playing") is True
        page.keyboard.press(" ")
        assert p.eval("() => !!window.viewer.S.playing") is False
    finally:
        p.close()


def test_a_reconnect_clears_the_events_list_and_a_find_under_way(
    browser,  # noqa: F811
    tmp_path,
    monkeypatch,
):
    import time

    from chronocl.events import run as events_run
    from chronocl.viewer.server import ViewerServer

    path = tmp_path / "blobs.zarr"
    TimeSeries.from_array(series(), source="blobs").save(path)
    first = ViewerServer([path])
    first.start()
    second = None
    p = Page(browser, first, 1400, 900)
    try:
        page = p.page
        page.click("#events-find")
        page.wait_for_function("() => window.viewer.events && window.viewer.events.found")
        assert page.locator("#events-list li[data-index]").count() == 3
        label = events_run.label_step

        def slow(*args, **kwargs):
            time.sleep(2.0)
            return label(*args, **kwargs)

        monkeypatch.setattr(events_run, "label_step", slow)
        page.click("#events-find")  # under way when the server stops
        page.wait_for_function("() => window.viewer.events && window.viewer.events.finding")
        assert page.inner_text("#events-text").startswith("finding events")
        first.stop()
        page.wait_for_function(
            "() => document.body.dataset.connection === 'retrying'", timeout=20_000
        )
        monkeypatch.setattr(events_run, "label_step", label)
        second = ViewerServer([path], port=first.port, token=first.token)
        frames = p.eval("() => window.viewer.frames")
        second.start()
        # A frame on the new socket: its info (which clears the events) came before it.
        page.wait_for_function(
            "([n]) => window.viewer.connects === 2 && window.viewer.frames > n",
            arg=[frames],
            timeout=30_000,
        )
        p.settle({"seq": 0})
        assert p.eval("() => window.viewer.events") is None
        assert page.locator("#events-list li").count() == 0
        assert page.locator("#events-tracks li").count() == 0
        assert not page.inner_text("#events-text").startswith("finding")
        # A find on the new socket works as before.
        page.click("#events-find")
        page.wait_for_function("() => window.viewer.events && window.viewer.events.found")
        assert page.locator("#events-list li[data-index]").count() == 3
        p.problems.clear()  # the refused reconnects are logged by the browser, not errors
    finally:
        p.close()
        first.stop()
        if second is not None:
            second.stop()
