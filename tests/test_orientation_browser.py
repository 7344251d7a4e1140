"""The viewer's up menu in Chromium: choosing z turns the frame and the axes triad (z now
points up), the standard views follow the up axis (+Y with z up is the front view at
azimuth 0, elevation 0), and camera reset keeps the chosen axis.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from .test_viewer_page_browser import Page, browser, server, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, full_size_frames  # noqa: F401

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

# Where each axis's arm ends in the first view's triad: the mean offset from the canvas
# centre of its coloured pixels (red x, green y, blue z), screen y growing downwards, and their
# count (0 for an arm pointing away from the viewer, which is drawn faint).
ARMS = """() => {
  const c = document.querySelector('.view .triad');
  const px = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  const sums = [[0, 0, 0], [0, 0, 0], [0, 0, 0]];
  for (let k = 0; k < px.length; k += 4) {
    if (px[k + 3] < 200) continue;
    const [r, g, b] = [px[k], px[k + 1], px[k + 2]];
    const axis = r > 200 && g < 120 && b < 120 ? 0 : g > 180 && r < 120 && b < 120 ? 1
      : b > 200 && r < 120 ? 2 : -1;
    if (axis < 0) continue;
    const i = k / 4;
    sums[axis][0] += (i % c.width) - c.width / 2;
    sums[axis][1] += Math.floor(i / c.width) - c.height / 2;
    sums[axis][2] += 1;
  }
  return {up: c.dataset.up, arms: sums.map(([x, y, n]) => [n ? x / n : 0, n ? y / n : 0, n])};
}"""


def test_the_up_menu_turns_the_view_triad_and_standard_views(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        opening = p.last()
        assert page.input_value("#up") == "y"
        before = p.eval(ARMS)
        assert before["up"] == "y" and before["arms"][1][1] < -3  # y points up
        page.select_option("#up", "z")
        turned = p.settle(opening)
        assert turned["digest"] != opening["digest"]
        cam = p.eval("() => window.viewer.S.state.camera")
        assert cam["up"] == "z" and (cam["azimuth"], cam["elevation"]) == (30, 20)
        after = p.eval(ARMS)
        assert after["up"] == "z" and after["arms"][2][1] < -3  # now z points up
        assert abs(after["arms"][1][1]) < abs(before["arms"][1][1]) / 2  # y lies down, away
        # +Y with z up: the front view, straight along +y.
        before_y = p.last()
        page.keyboard.press("y")
        front = p.settle(before_y)
        cam = p.eval("() => window.viewer.S.state.camera")
        assert (cam["azimuth"], cam["elevation"], cam["up"]) == (0, 0, "z")
        # Reset returns to the opening angles and keeps the axis chosen.
        page.keyboard.press("r")
        p.settle(front)
        cam = p.eval("() => window.viewer.S.state.camera")
        assert (cam["azimuth"], cam["elevation"], cam["up"]) == (30, 20, "z")
        assert page.input_value("#up") == "z"
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-up-z-1400x900.png"))
    finally:
        p.close()
