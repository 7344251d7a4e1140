"""The viewer's data colour bar and time colours that follow a colour map, in Chromium.

Choosing a colour-map preset in the TF editor sets the time colours to lightness (one undo
step with the map) and shows a colour bar beside each view's time legend: the map's colours
over the value range the view used, ticks at nice numbers in data units. Time colours chosen
in the menu are kept when a map is chosen after them.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import itertools
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

# The first view's colour bar: whether it shows, its ticks and range, and its pixels at
# fractions of the bar's length (CSS px from the canvas's data-bar, read in device pixels).
COLOUR_BAR = """(fractions) => {
  const c = document.querySelector('#views .view canvas.colorbar');
  if (c.hidden || !c.dataset.bar) return {hidden: c.hidden, shown: c.offsetWidth > 0};
  const [x0, x1, y] = c.dataset.bar.split(',').map(Number);
  const dpr = window.devicePixelRatio || 1, ctx = c.getContext('2d');
  const rgb = fractions.map((f) => Array.from(ctx.getImageData(
    Math.round((x0 + f * (x1 - x0)) * dpr), Math.round(y * dpr), 1, 1).data.slice(0, 3)));
  return {hidden: c.hidden, shown: c.offsetWidth > 0, ticks: c.dataset.ticks,
          range: c.dataset.range.split(',').map(Number), rgb};
}"""
FRACTIONS = [0.02, 0.25, 0.5, 0.75, 0.98]


def viridis(fractions) -> np.ndarray:
    from matplotlib import colormaps

    return colormaps["viridis"](np.asarray(fractions))[:, :3] * 255


def choose(p: Page, selector: str, value: str) -> dict:
    before = p.last()
    p.page.select_option(selector, value)
    return p.settle(before)


def test_a_colour_map_preset_brings_its_colour_bar_and_lightness_time_colours(
    browser,  # noqa: F811
    server,  # noqa: F811
    tmp_path,
):
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        assert p.eval(COLOUR_BAR, FRACTIONS)["hidden"]  # the white data TF: no colour bar
        assert page.input_value("#time-color") == "rgb"

        choose(p, "#tf-colormap", "viridis")
        assert page.input_value("#time-color") == "lightness"
        assert p.eval("() => window.viewer.S.state.time_tf.color") == "lightness"
        # The time legend shows the lightness ramp: grey oldest, white newest.
        legend = p.eval("() => window.viewer.S.legend")
        assert legend[0]["rgb"] == [0.35, 0.35, 0.35] and legend[-1]["rgb"] == [1, 1, 1]

        bar = p.eval(COLOUR_BAR, FRACTIONS)
        assert not bar["hidden"] and bar["shown"]
        got = np.array(bar["rgb"], dtype=float)
        assert np.abs(got - viridis(FRACTIONS)).max() <= 12, got  # the map, left to right
        # Its range is the one the view used (the frame's), its ticks nice numbers within it.
        sent = p.eval("() => window.viewer.S.colorbars[0]")
        assert bar["range"] == pytest.approx(sent["range"]) and sent["title"] == "value"
        lo, hi = bar["range"]
        ticks = [float(t) for t in bar["ticks"].split(",")]
        assert len(ticks) >= 2 and lo - 1e-9 <= ticks[0] and ticks[-1] <= hi + 1e-9, ticks
        gaps = {round(b - a, 9) for a, b in itertools.pairwise(ticks)}
        assert len(gaps) == 1, ticks
        gap = gaps.pop()
        assert round(gap / 10 ** np.floor(np.log10(gap)), 6) in (1, 2, 5), ticks
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-colour-bar.png"))

        # The legend switch hides the colour bar with the time legend.
        page.keyboard.press("l")
        assert not p.eval(COLOUR_BAR, FRACTIONS)["shown"]
        page.keyboard.press("l")
        assert p.eval(COLOUR_BAR, FRACTIONS)["shown"]

        # One undo step takes back the map and the time colours together.
        before = p.last()
        page.keyboard.press("Control+z")
        p.settle(before)
        assert page.input_value("#time-color") == "rgb"
        assert p.eval(COLOUR_BAR, FRACTIONS)["hidden"]

        # Time colours chosen in the menu stay when a map is chosen after them.
        choose(p, "#time-color", "warm-cool")
        choose(p, "#tf-colormap", "magma")
        assert page.input_value("#time-color") == "warm-cool"
        assert not p.eval(COLOUR_BAR, FRACTIONS)["hidden"]
    finally:
        p.close()
