"""Views set apart (issue 49), in Chromium: a new view copies the selected view's mode, and its
own camera and TFs where it has them; each
view's links (camera, data TF, time TF) shown as toggles in its head band; a link toggled off
gives the view its own copy, which the drags on its picture, the TF editor and the time TF
controls then edit (the other view unchanged); the links kept by a saved session, the URL's
#state= and undo; a link toggled on again drops the copy.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import base64
import io
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


# Panel k's image as the page shows it, as PNG (a data URL).
PANEL_PNG = """async (k) => {
  const img = document.querySelectorAll('#views .view img')[k];
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


def panel(p: Page, k: int) -> np.ndarray:
    from PIL import Image

    url = p.eval(PANEL_PNG, k)
    data = base64.b64decode(url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(np.int16)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal frames: same size, the JPEGs within the encoder's tolerance."""
    return a.shape == b.shape and float(np.abs(a - b).mean()) < 1.0


def state(p: Page) -> dict:
    return p.eval("() => JSON.parse(JSON.stringify(window.viewer.S.state))")


def links(p: Page, k: int) -> dict:
    """View k's toggles: {link: pressed (own)}."""
    return p.eval(
        """(k) => Object.fromEntries([...document.querySelectorAll('#views .view')[k]
             .querySelectorAll('.link')].map((b) => [b.dataset.link, b.getAttribute('aria-pressed')
             === 'true']))""",
        k,
    )


def act(p: Page, do) -> dict:
    """`do()`, then the settled frame after it."""
    before = p.last()
    do()
    return p.settle(before)


def toggle(p: Page, k: int, link: str) -> dict:
    return act(
        p,
        lambda: (
            p.page.locator(f"#views .view >> nth={k}").locator(f'.link[data-link="{link}"]').click()
        ),
    )


def centre(p: Page, k: int) -> dict:
    box = p.page.locator("#views .view img").nth(k).bounding_box()
    return {"x": box["x"] + box["width"] / 2, "y": box["y"] + box["height"] / 2}


def test_views_set_apart_edited_saved_and_restored(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1200, 720)
    try:
        page = p.page
        # A new view copies the selected view's mode (not the first mode of the list).
        act(p, lambda: page.locator("#views .view .mode").first.select_option("max"))
        act(p, lambda: page.select_option("#nviews", "2"))
        page.wait_for_timeout(300)  # the resize observer's debounce
        p.settle({"seq": 0})
        s = state(p)
        assert [v["mode"] for v in s["views"]] == ["max", "max"]
        assert all(v["camera"] is None and v["data_tf"] is None for v in s["views"])
        assert links(p, 0) == links(p, 1) == {"camera": False, "data_tf": False, "time_tf": False}
        assert same(panel(p, 0), panel(p, 1))  # linked: one picture twice

        # The camera unlinked: a drag on view 2 turns its own camera, view 1 stays.
        toggle(p, 1, "camera")
        assert links(p, 1)["camera"] and p.eval("() => window.viewer.S.selectedView") == 1
        first = panel(p, 0)
        shared = state(p)["camera"]
        act(
            p,
            lambda: drag(
                page, centre(p, 1), {"x": centre(p, 1)["x"] + 90, "y": centre(p, 1)["y"] + 30}
            ),
        )
        s = state(p)
        assert s["camera"] == shared and s["views"][1]["camera"]["azimuth"] != shared["azimuth"]
        assert same(panel(p, 0), first) and not same(panel(p, 1), first)

        # The data TF unlinked and edited in the editor: view 2's own, view 1's the shared one.
        toggle(p, 1, "data_tf")
        assert page.inner_text("#own-data_tf") == "· view 2's own"
        before = p.last()
        at = p.eval("() => window.viewer.tfPointAt(1)")
        drag(page, at, {"x": at["x"] - 30, "y": at["y"] - 40})
        p.settle(before)
        s = state(p)
        assert s["views"][1]["data_tf"]["points"] != s["data_tf"]["points"]
        assert same(panel(p, 0), first)

        # The time TF unlinked: the opacity shape chosen is view 2's only.
        toggle(p, 1, "time_tf")
        act(p, lambda: page.select_option("#time-alpha", "hat"))
        s = state(p)
        assert s["views"][1]["time_tf"]["alpha"] == "hat" and s["time_tf"]["alpha"] == "constant"
        assert same(panel(p, 0), first)
        assert links(p, 1) == {"camera": True, "data_tf": True, "time_tf": True}
        assert links(p, 0) == {"camera": False, "data_tf": False, "time_tf": False}
        # Selecting view 1 (a click probes it) shows the shared TFs in the editors again.
        page.mouse.click(**centre(p, 0))
        page.wait_for_function("() => window.viewer.S.selectedView === 0")
        assert page.input_value("#time-alpha") == "constant"
        assert page.is_hidden("#own-data_tf")
        shot = os.path.join(shots_dir(tmp_path), "viewer-views-set-apart.png")
        page.screenshot(path=shot)
        apart = [panel(p, 0), panel(p, 1)]

        # Saved as a session: the links in it; the page afresh from the URL's #state= shows
        # the same pictures, its toggles pressed as they were.
        with page.expect_download() as got:
            page.click("#save-session")
        session = json.loads(open(got.value.path()).read())
        assert session["views"][0]["camera"] is None
        assert session["views"][1]["time_tf"]["alpha"] == "hat"
        fragment = page.evaluate("() => location.hash")
        page.goto(server.url + fragment)
        page.wait_for_function("() => window.viewer && window.viewer.full >= 1", timeout=60_000)
        p.settle()
        assert same(panel(p, 0), apart[0]) and same(panel(p, 1), apart[1])
        assert links(p, 1) == {"camera": True, "data_tf": True, "time_tf": True}

        # Linked again: the copy dropped, the view drawn with the shared camera; undo brings
        # the copy back.
        page.mouse.click(**centre(p, 1))
        page.wait_for_function("() => window.viewer.S.selectedView === 1")
        assert page.input_value("#time-alpha") == "hat"  # the editors show view 2's own
        assert page.inner_text("#own-time_tf") == "· view 2's own"
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-views-set-apart-2.png"))
        # A view added copies the selected view's mode and its own camera and TFs.
        act(p, lambda: page.select_option("#nviews", "3"))
        s = state(p)
        for k in ("camera", "data_tf", "time_tf"):
            assert s["views"][2][k] == s["views"][1][k] and s["views"][0][k] is None
        act(p, lambda: page.select_option("#nviews", "2"))
        toggle(p, 1, "camera")
        assert state(p)["views"][1]["camera"] is None and not links(p, 1)["camera"]
        assert not same(panel(p, 1), apart[1])
        act(p, lambda: page.keyboard.press("Control+z"))
        assert state(p)["views"][1]["camera"] is not None
        assert same(panel(p, 1), apart[1])
    finally:
        p.close()
