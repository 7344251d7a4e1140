"""A count view's legend in Chromium (issue 49): count colours a voxel by the fraction of the
window's steps it is present in, so its legend is the count bar (the data TF's colours and
opacity from no step to every step, the window's number of steps, ticks in per cent), drawn
in place of the time legend whose step colours mean nothing there; the frame's `countbars`
carries it, null for the views whose colour tells time.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from .test_viewer_page_browser import Page, browser, server, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

# Each view's legend canvas: what it shows (its data-kind), its ticks, and, for a count bar,
# its pixels at fractions of the bar's length (device pixels).
LEGENDS = """(fractions) => [...document.querySelectorAll('#views .view canvas.legend')]
  .map((c) => {
  const d = c.dataset, out = {kind: d.kind, ticks: d.ticks, steps: d.steps, shown: !c.hidden};
  if (d.bar) {
    const [x0, x1, y] = d.bar.split(',').map(Number);
    const dpr = window.devicePixelRatio || 1, ctx = c.getContext('2d');
    out.rgb = fractions.map((f) => Array.from(ctx.getImageData(
      Math.round((x0 + f * (x1 - x0)) * dpr), Math.round(y * dpr), 1, 1).data.slice(0, 3)));
  }
  return out;
})"""
FRACTIONS = [0.02, 0.5, 0.98]


def choose(p: Page, selector: str, value: str, nth: int = 0) -> dict:
    before = p.last()
    p.page.locator(selector).nth(nth).select_option(value)
    return p.settle(before)


def test_count_view_shows_the_count_bar_not_the_step_legend(
    browser,  # noqa: F811
    server,  # noqa: F811
    tmp_path,
):
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        first = p.eval(LEGENDS, FRACTIONS)[0]
        assert first["kind"] == "time" and first["ticks"].split(",")[0] == "1"  # steps 1:11
        assert p.eval("() => window.viewer.S.countbars") == [None]

        choose(p, "#views .view select.mode", "count")
        bar = p.eval("() => window.viewer.S.countbars[0]")
        steps = len(p.eval("() => window.viewer.S.legend"))
        assert bar["kind"] == "fraction" and bar["steps"] == steps == 10
        assert bar["ends"] == ["no step", "every step"]
        legend = p.eval(LEGENDS, FRACTIONS)[0]
        assert legend["shown"] and legend["kind"] == "fraction"
        assert legend["ticks"] == "0%,25%,50%,75%,100%" and legend["steps"] == ""
        # The shared data TF is white: the bar is grey, dark where few steps show, bright
        # where all do; nothing of the blue-to-red time colours.
        rgb = np.array(legend["rgb"], dtype=float)
        assert np.abs(rgb - rgb.mean(axis=1, keepdims=True)).max() <= 3, rgb
        assert rgb[0].mean() < 90 < 200 < rgb[-1].mean(), rgb
        assert p.eval("() => document.querySelector('#views .view canvas.colorbar').hidden")
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-count-legend.png"))

        # A second view copies count; turned to alpha it has the step legend again, while
        # the first keeps its count bar.
        choose(p, "#nviews", "2")
        assert [item["kind"] for item in p.eval(LEGENDS, FRACTIONS)] == ["fraction", "fraction"]
        choose(p, "#views .view select.mode", "alpha", nth=1)
        kinds = [item["kind"] for item in p.eval(LEGENDS, FRACTIONS)]
        assert kinds == ["fraction", "time"]
        assert [b and b["kind"] for b in p.eval("() => window.viewer.S.countbars")] == [
            "fraction",
            None,
        ]
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-count-and-alpha.png"))
    finally:
        p.close()
