"""The viewer page in Debian's chromium, driven by Playwright: frames appear and change with
orbit, mode, window brush and TF edits; the probe plots; without the token nothing loads."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

pytest.importorskip("starlette")
playwright_api = pytest.importorskip("playwright.sync_api")

from chronocl import modes  # noqa: E402

from .viewer_helpers import CHROMIUM, SETTLED_FRAME, launch_browser, make_stores, start_server  # noqa: E402

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = start_server(make_stores(tmp_path_factory.mktemp("viewer-browser")))
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def browser():
    yield from launch_browser()


@pytest.fixture
def page(browser, server):
    # Playwright's waiting helpers evaluate strings, which the page's CSP forbids.
    context = browser.new_context(viewport={"width": 1280, "height": 820}, bypass_csp=True)
    page = context.new_page()
    problems: list[str] = []
    page.on("pageerror", lambda e: problems.append(str(e)))
    page.goto(server.url)
    page.wait_for_function("() => window.viewer && window.viewer.full >= 1", timeout=60_000)
    yield page
    assert problems == []
    context.close()


def last(page) -> dict:
    return page.evaluate("() => window.viewer.last")


def settle(page, before: dict) -> dict:
    """Wait for the final frame (full quality, level and size) answering the newest request;
    returns viewer.last."""
    page.wait_for_function(SETTLED_FRAME, arg=[before["seq"]], timeout=60_000)
    return last(page)


def drag(page, start: dict, end: dict, steps: int = 8) -> None:
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.move(end["x"], end["y"], steps=steps)
    page.mouse.up()


def test_page_loads_with_the_token_and_shows_a_frame(page):
    frame = settle(page, {"seq": 0})
    assert frame["views"] == 1
    size = page.evaluate("() => document.querySelector('.view img').naturalWidth")
    assert size >= 64
    assert "token" not in page.url  # dropped from the address bar; the cookie keeps access
    # the status line says what the frame took; the stages' times are in its tooltip
    status = page.inner_text("#status")
    assert re.search(r"(integrated|recoloured|drawn) in \d+ ms", status), status
    assert "upload" not in status and "encode" not in status
    tooltip = page.get_attribute("#status", "title")
    assert re.search(r"render [\d.]+ ms .* encode [\d.]+ ms", tooltip), tooltip
    assert re.search(r"integrate [\d.]+ ms \(reading steps [\d.]+ ms of it\)", tooltip), tooltip
    # The mode menu is the server's registry, with each mode's summary as its tooltip.
    menu = page.eval_on_selector_all(
        ".view select.mode option", "os => os.map(o => [o.value, o.title])"
    )
    assert menu == [[n, modes.get(n).summary] for n in modes.names()]


def test_without_the_token_the_page_and_the_socket_are_refused(browser, server):
    context = browser.new_context(bypass_csp=True)
    page = context.new_page()
    response = page.goto(server.base + "/")
    assert response.status == 403
    assert page.goto(server.base + "/static/app.js").status == 403
    outcome = page.evaluate(
        """(url) => new Promise((done) => {
             const ws = new WebSocket(url);
             ws.onopen = () => done('open');
             ws.onclose = (e) => done('closed ' + e.code);
           })""",
        f"ws://127.0.0.1:{server.port}/ws",
    )
    assert outcome.startswith("closed")
    context.close()


def test_dragging_changes_the_frame(page):
    before = settle(page, {"seq": 0})
    box = page.locator(".view img").first.bounding_box()
    centre = {"x": box["x"] + box["width"] / 2, "y": box["y"] + box["height"] / 2}
    drag(page, centre, {"x": centre["x"] + 120, "y": centre["y"] + 30})
    after = settle(page, before)
    assert after["digest"] != before["digest"]
    camera = page.evaluate("() => window.viewer.S.state.camera")
    assert camera["azimuth"] != 30.0


def test_mode_window_and_tf_each_give_a_new_frame(page):
    frame = settle(page, {"seq": 0})
    seen = {frame["digest"]}

    page.select_option('.view[data-i="0"] select.mode', "max")
    frame = settle(page, frame)
    assert frame["digest"] not in seen
    assert "max" in page.inner_text('.view[data-i="0"] .view-label')
    seen.add(frame["digest"])

    # Brush a new window over steps 0..4 on the timeline.
    a = page.evaluate("() => window.viewer.timelineAt(0)")
    b = page.evaluate("() => window.viewer.timelineAt(4)")
    drag(page, a, b)
    frame = settle(page, frame)
    assert page.evaluate("() => window.viewer.S.state.window") == {"t0": 0, "t1": 5, "stride": 1}
    assert frame["digest"] not in seen
    seen.add(frame["digest"])

    # Arrow keys slide it.
    page.keyboard.press("ArrowRight")
    frame = settle(page, frame)
    assert page.evaluate("() => window.viewer.S.state.window")["t0"] == 1
    assert frame["digest"] not in seen
    seen.add(frame["digest"])

    # Drag a data TF point (the third) up: more opaque.
    p = page.evaluate("() => window.viewer.tfPointAt(2)")
    before_points = page.evaluate("() => window.viewer.S.state.data_tf.points.map(p => p[4])")
    drag(page, p, {"x": p["x"] - 20, "y": p["y"] - 40})
    frame = settle(page, frame)
    after_points = page.evaluate("() => window.viewer.S.state.data_tf.points.map(p => p[4])")
    assert after_points[2] > before_points[2]
    assert frame["digest"] not in seen


def test_probe_plot_appears(page):
    settle(page, {"seq": 0})
    box = page.locator(".view img").first.bounding_box()
    page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.wait_for_function(
        "() => window.viewer.probe && document.querySelector('#probe').dataset.drawn",
        timeout=60_000,
    )
    probe = page.evaluate("() => window.viewer.probe")
    assert probe["voxel"] is not None and len(probe["values"]) == 12
    assert "voxel x=" in page.inner_text("#probe-text")
    # A shift-drag across the middle probes a box: mean with its min-max band, exported as CSV.
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.keyboard.down("Shift")
    page.mouse.move(cx - 0.08 * box["width"], cy - 0.06 * box["height"])
    page.mouse.down()
    page.mouse.move(cx + 0.08 * box["width"], cy + 0.06 * box["height"], steps=6)
    page.mouse.up()
    page.keyboard.up("Shift")
    page.wait_for_function("() => window.viewer.probe && window.viewer.probe.box", timeout=60_000)
    probe = page.evaluate("() => window.viewer.probe")
    assert len(probe["min"]) == len(probe["max"]) == 12
    assert page.inner_text("#probe-text").startswith("box x ")
    with page.expect_download() as got:
        page.click("#probe-csv")
    assert got.value.suggested_filename.startswith("vortex-probe-x")
    lines = Path(got.value.path()).read_text().splitlines()
    assert lines[0] == "step,time,mean,min,max,in_window" and len(lines) == 13


def test_parallel_views_screenshot(page, tmp_path):
    frame = settle(page, {"seq": 0})
    page.select_option("#nviews", "3")
    frame = settle(page, frame)
    assert frame["views"] == 3
    labels = page.locator(".view-label").all_inner_texts()
    # New views copy the selected view's mode (the first registered one here).
    assert [t.split(",")[0] for t in labels] == [modes.names()[0]] * 3
    shot = tmp_path / "viewer.png"
    page.screenshot(path=str(shot))
    assert shot.stat().st_size > 10_000
