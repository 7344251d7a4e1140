"""The viewer's lighting in Chromium: the toggle lights the frame, a strength slider changes
it, and switching off gives back the very frame the page opened with. Screenshots go to
$CHRONOCL_SCREENSHOTS (else the test's temporary folder)."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from .test_viewer_page_browser import Page, browser, server, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

SLIDE = """([id, value]) => {
  const el = document.getElementById(id);
  el.value = value;
  el.dispatchEvent(new Event('change'));
}"""


def test_lighting_toggle_and_strengths(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1024, 640)
    try:
        page = p.page
        opening = p.last()
        assert p.eval("() => window.viewer.S.state.shading.enabled") is False
        page.click("#lighting summary")
        assert page.is_disabled("#shading-diffuse")  # strengths wait for the toggle
        page.check("#shading-on")
        lit = p.settle(opening)
        assert lit["digest"] != opening["digest"]
        shading = p.eval("() => window.viewer.S.state.shading")
        assert shading["enabled"] is True and page.is_enabled("#shading-diffuse")
        page.locator("#views").screenshot(path=os.path.join(shots_dir(tmp_path), "lit.png"))
        page.locator("#lighting").screenshot(
            path=os.path.join(shots_dir(tmp_path), "lighting-panel.png")
        )

        p.eval(SLIDE, ["shading-ambient", "1.5"])
        brighter = p.settle(lit)
        assert brighter["digest"] not in (lit["digest"], opening["digest"])
        assert p.eval("() => window.viewer.S.state.shading.ambient") == 1.5

        page.uncheck("#shading-on")
        off = p.settle(brighter)
        assert off["digest"] == opening["digest"]  # unlit: the opening frame, bit for bit
    finally:
        p.close()
