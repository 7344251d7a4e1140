"""Keeping the viewer's state, in Chromium: a session saved, the page opened afresh, the
session loaded, and the frame the one before; the URL's #state= restoring it too; undo after a
TF edit bringing back the frame before it, redo the edited one (Ctrl+Z, Ctrl+Shift+Z); the
time legend drawn in each view, in the frame's time colours, and hidden with L.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import base64
import io
import itertools
import json
import os

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from .test_viewer_page_browser import Page, browser, drag, server, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, full_size_frames  # noqa: F401

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)


@pytest.fixture(autouse=True)
def _full_size(full_size_frames):  # noqa: F811
    """Every test here compares frames: all drawn at full size."""


# The first panel's image as the page shows it, as PNG (a data URL).
PANEL_PNG = """async () => {
  const img = document.querySelector('#views .view img');
  // a newer frame may replace the picture mid-decode (EncodingError): decode that one
  for (let k = 0; ; k++) {
    try { await img.decode(); break; } catch (e) { if (k > 20) throw e; }
    await new Promise((r) => setTimeout(r, 50));
  }
  const c = document.createElement('canvas');
  c.width = img.naturalWidth;
  c.height = img.naturalHeight;
  c.getContext('2d').drawImage(img, 0, 0);
  return c.toDataURL('image/png');
}"""


def panel(p: Page) -> np.ndarray:
    from PIL import Image

    url = p.eval(PANEL_PNG)
    data = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(np.int16)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal frames: same size, the JPEGs within the encoder's tolerance."""
    return a.shape == b.shape and float(np.abs(a - b).mean()) < 1.0


def edit_tf(p: Page) -> dict:
    """Drag the TF's third point down and left (one edit); returns the settled frame."""
    before = p.last()
    at = p.eval("() => window.viewer.tfPointAt(2)")
    drag(p.page, at, {"x": at["x"] - 40, "y": at["y"] + 35})
    return p.settle(before)


def press(p: Page, key: str) -> dict:
    before = p.last()
    p.page.keyboard.press(key)
    return p.settle(before)


def open_at(p: Page, url: str) -> None:
    p.page.goto(url)
    p.page.wait_for_function("() => window.viewer && window.viewer.full >= 1", timeout=60_000)
    p.settle()


def test_session_saved_loaded_and_carried_by_the_url(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 900, 640)
    try:
        page = p.page
        page.keyboard.press("x")  # a camera, a window and a TF other than the opening ones
        page.keyboard.press("ArrowRight")
        edit_tf(p)
        shown = panel(p)
        with page.expect_download() as got:
            page.click("#save-session")
        saved = tmp_path / got.value.suggested_filename
        got.value.save_as(saved)
        session = json.loads(saved.read_text())
        assert session["chronocl_session"] == 1 and session["dataset"]["name"] == "vortex"
        assert session["camera"]["azimuth"] == -90 and session["window"]["t0"] > 1
        fragment = page.evaluate("() => location.hash")
        assert fragment.startswith("#state=")

        open_at(p, server.url)  # the page afresh: the opening view
        assert not same(panel(p), shown)
        before = p.last()
        page.set_input_files("#session-file", str(saved))
        p.settle(before)
        assert same(panel(p), shown)
        assert p.eval("() => window.viewer.S.state.camera.azimuth") == -90
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-session-loaded.png"))

        open_at(p, server.url + fragment)  # the URL alone restores the view
        assert same(panel(p), shown)
        # A fragment that does not fit is reported; the page opens the default view.
        bad = page.evaluate(
            """() => { const s = JSON.parse(atob(location.hash.slice(7)
                 .replace(/-/g, '+').replace(/_/g, '/')));
               s.camera.zoom = 99; return btoa(JSON.stringify(s)).replace(/=+$/, ''); }"""
        )
        open_at(p, f"{server.url}#state={bad}")
        assert "camera.zoom is 99" in page.inner_text("#status") or p.eval(
            "() => window.viewer.errors.some(e => e.message.includes('camera.zoom is 99'))"
        )
    finally:
        p.close()


def test_undo_and_redo_a_tf_edit(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 900, 640)
    try:
        page = p.page
        opening = panel(p)
        points = p.eval("() => JSON.stringify(window.viewer.S.state.data_tf.points)")
        assert page.is_disabled("#undo") and page.is_disabled("#redo")
        edit_tf(p)
        edited = panel(p)
        assert not same(edited, opening)
        assert p.eval("() => window.viewer.history.undo") == 1

        press(p, "Control+z")
        assert same(panel(p), opening)
        assert p.eval("() => JSON.stringify(window.viewer.S.state.data_tf.points)") == points
        assert page.is_disabled("#undo") and not page.is_disabled("#redo")
        press(p, "Control+Shift+Z")
        assert same(panel(p), edited)
        before = p.last()
        page.click("#undo")  # the button does the same
        p.settle(before)
        assert same(panel(p), opening)
        page.focus("#projection")  # in a menu Ctrl+Y is the page's redo too
        press(p, "Control+y")
        assert same(panel(p), edited)
        # The ? list names the keys.
        page.keyboard.press("?")
        keys = page.inner_text("#help-keys")
        assert "Ctrl+Z" in keys and "Ctrl+Shift+Z, Ctrl+Y" in keys
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-undo-keys.png"))
    finally:
        p.close()


# The legend canvas's pixel at step k's colour cell, and whether the canvas shows.
LEGEND_CELL = """([k]) => {
  const c = document.querySelector('#views .view canvas.legend');
  const at = window.viewer.legendCell(k), dpr = window.devicePixelRatio || 1;
  const px = c.getContext('2d').getImageData(Math.round(at.x * dpr), Math.round(at.y * dpr), 1, 1);
  return {rgb: Array.from(px.data.slice(0, 3)), hidden: c.hidden, steps: c.dataset.steps};
}"""


def test_time_legend_in_each_view(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 900, 640)
    try:
        legend = p.eval("() => window.viewer.S.legend")
        assert len(legend) == 10  # the opening window's steps
        for k in (0, len(legend) - 1):  # the oldest and newest step's time colour
            got = p.eval(LEGEND_CELL, [k])
            assert not got["hidden"]
            assert got["steps"] == ",".join(str(item["step"]) for item in legend)
            want = [round(255 * c) for c in legend[k]["rgb"]]
            assert max(abs(a - b) for a, b in zip(got["rgb"], want, strict=True)) <= 3
        # Its ticks: evenly spaced multiples of 1, 2 or 5 within the window's steps 1..10.
        ticks = [
            float(t)
            for t in p.eval(
                "() => document.querySelector('#views .view canvas.legend').dataset.ticks"
            ).split(",")
        ]
        gaps = {round(b - a, 9) for a, b in itertools.pairwise(ticks)}
        assert len(ticks) >= 2 and len(gaps) == 1 and gaps <= {1, 2, 5}, ticks
        assert all(t % next(iter(gaps)) == 0 and 1 <= t <= 10 for t in ticks), ticks
        p.page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-time-legend.png"))
        p.page.keyboard.press("l")
        assert p.eval(LEGEND_CELL, [0])["hidden"]
        assert not p.page.is_checked("#legend-on")
        p.page.click("#legend-on")
        assert not p.eval(LEGEND_CELL, [0])["hidden"]
    finally:
        p.close()
