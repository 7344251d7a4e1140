"""The slice panel in Chromium (issue 49, slices through time; `static/slice.js`): opened, a
z index chosen, it shows the `slice` reply's picture (its natural size the reply's size, scaled
to the panel's width); the pointer over the voxel grid reads out the voxel, the step that won
it (a max view: the t_index `chronocl.integrate` gives there) and the series' value, over the
colours and over the step map alike, in the panel and shown larger over the views; the plane's
outline is drawn on the view's panel and follows the index; an alpha view, which keeps no
t_index, says so; folding the panel takes the outline away; no page errors.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from playwright.sync_api import TimeoutError as PlaywrightTimeoutError

import chronocl
from chronocl.data.series import open_series

from .test_viewer_count_legend_browser import choose
from .test_viewer_page_browser import Page, browser, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, make_stores, serving

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    return make_stores(tmp_path_factory.mktemp("viewer-slice"))


@pytest.fixture(scope="module")
def server(stores):
    yield from serving(stores)


# The slice reply shown, without its picture's bytes, and the picture element's sizes.
SHOWN = """(id) => {
  const s = window.viewer.slice, img = document.getElementById(id || 'slice-pic');
  if (!s) return null;
  const r = img.getBoundingClientRect();
  const side = document.getElementById('slice-panel').getBoundingClientRect();
  return {id: s.id, slice: s.slice, size: s.size, box: s.box, grid: s.grid, t_index: s.t_index,
          pictures: s.layout.pictures,
          natural: [img.naturalWidth, img.naturalHeight], shown: [r.x, r.y, r.width, r.height],
          panel: [side.x, side.width], complete: img.complete && img.getAttribute('src') === s.png};
}"""


# The slice plane's outline drawn on the first view's panel: [x, y] fractions of the panel.
CUT = """() => {
  const pts = document.querySelector('#views .view .slice-cut').getAttribute('points') || '';
  return pts.split(' ').filter(Boolean).map((xy) => xy.split(',').map(Number));
}"""


def wait_slice(p: Page, spec: str, after: int = 0) -> dict:
    p.page.wait_for_function(
        """([spec, after]) => {
          const s = window.viewer.slice, img = document.getElementById('slice-pic');
          return !!s && s.slice === spec && s.id > after && img.complete && img.naturalWidth > 0
            && img.getAttribute('src') === s.png; }""",
        arg=[spec, after],
        timeout=60_000,
    )
    return p.eval(SHOWN)


def hover(p: Page, u: float, v: float, after: int = 0, panel: int = 0, img="slice-pic") -> dict:
    """The pointer at (u, v) of the voxel grid in the reply's picture `panel` (0: the colours,
    1: the step map; the grid's `box` is in each of the layout's pictures) of the picture `img`;
    returns the read-out that answers it. Where the pointer goes is read from the picture shown
    when it moves, and again while the read-out is waited for: the side panel's sections above
    it change height as their notes come (a histogram's, late under load), which moved the
    picture, and a picture asked again may lay out otherwise; the pointer follows it there.
    Where no read-out came in 5 s with the pointer still, it moves off and back: the page asks
    again only when the pointer moves (CI: a read-out never came in 60 s, the pointer still)."""
    end, placed = time.monotonic() + 60, None
    while True:
        now = p.eval(SHOWN, img)
        if now is None or not now["complete"] or not now["natural"][0]:
            assert time.monotonic() < end, "the slice picture never loaded"
            time.sleep(0.05)  # a picture still loading: no grid to point at yet
            continue
        x, y, w, _ = now["shown"]
        bx, by, bw, bh = now["box"]
        px, py = now["pictures"][panel][:2]
        scale = w / now["natural"][0]
        at = (x + (px + bx + u * bw) * scale, y + (py + by + v * bh) * scale)
        if at == placed:  # still: nothing new to ask, so a move off and back asks again
            p.page.mouse.move(at[0] + 1, at[1])
        p.page.mouse.move(*at)
        placed = at
        try:
            p.page.wait_for_function(
                "(after) => window.viewer.sliceReadout && window.viewer.sliceReadoutId > after",
                arg=after,
                timeout=5_000,
            )
            break
        except PlaywrightTimeoutError:
            if time.monotonic() > end:
                raise
    return p.eval(
        "() => ({id: window.viewer.sliceReadoutId, readout: window.viewer.sliceReadout,"
        " text: document.getElementById('slice-readout').textContent})"
    )


def test_the_slice_panel_shows_the_plane_and_reads_the_winning_step(
    browser,  # noqa: F811
    server,
    stores,
    tmp_path,
):
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        choose(p, "#views .view select.mode", "max")
        page.locator("#slice-panel summary").click()
        page.locator("#slice-axis").select_option("z")
        first = wait_slice(p, "z=15")  # the middle of 32 voxels, asked as the panel opens
        # An index picked on the slider (a range input: set, then its input event).
        page.eval_on_selector(
            "#slice-index", "(el) => { el.value = '20'; el.dispatchEvent(new Event('input')); }"
        )
        shown = wait_slice(p, "z=20", first["id"])
        assert page.locator("#slice-at").text_content() == "20 / 31"
        assert shown["natural"] == shown["size"]  # the reply's picture, as drawn
        # drawn at the side panel's width (device pixels: 1 here), the view's aspect
        # (in whole 16-pixel steps, a scrollbar's room kept whether one shows or not)
        gap = shown["panel"][1] - 2 - shown["size"][0]
        assert 0 <= gap <= 34, (shown["size"], shown["panel"])
        assert shown["grid"] == {"rows": 32, "cols": 32, "across": "x", "up": "y"}
        assert shown["t_index"] is True
        # Scaled to the panel's width, its aspect kept.
        _, _, w, h = shown["shown"]
        assert abs(w - (shown["panel"][1] - 2)) <= 2, (shown["shown"], shown["panel"])
        assert abs(h / w - shown["size"][1] / shown["size"][0]) < 0.02

        # The plane's outline on the view's panel: where z=20 cuts the box (four corners),
        # the reply's `outline`; another index moves it.
        cut = p.eval(CUT)
        assert len(cut) == 4 and p.eval("() => window.viewer.slice.outline") == cut
        page.eval_on_selector(
            "#slice-index", "(el) => { el.value = '4'; el.dispatchEvent(new Event('input')); }"
        )
        low = wait_slice(p, "z=4", shown["id"])
        p.page.wait_for_function(f"() => ({CUT})().length === 4")
        assert p.eval(CUT) != cut
        page.eval_on_selector(
            "#slice-index", "(el) => { el.value = '20'; el.dispatchEvent(new Event('input')); }"
        )
        shown = wait_slice(p, "z=20", low["id"])
        p.page.wait_for_function(f"() => ({CUT})().length === 4")

        state = p.eval("() => window.viewer.S.state")
        t0, t1, stride = (state["window"][k] for k in ("t0", "t1", "stride"))
        series = open_series(stores[0])
        cv = chronocl.integrate(series, f"{t0}:{t1}:{stride}", mode="max")
        # The pointer at voxel centres (a voxel is ~3 CSS pixels of the panel's picture): column
        # 9, row 12 from the top (y = 31 - 12).
        got = hover(p, 9.5 / 32, 12.5 / 32, shown["id"])
        read = got["readout"]
        vx, vy, vz = (read["voxel"][a] for a in "xyz")
        assert (vx, vy, vz) == (9, 19, 20)
        step = int(cv.t_index[vz, vy, vx])
        assert read["step"] == step >= 0
        assert read["value"] == pytest.approx(float(series.read_region(step, vz, vy, vx)))
        assert got["text"] == read["text"] and f"step {step}" in got["text"]
        assert got["text"].startswith(f"x={vx} y={vy} z={vz} (")
        # The same voxel from the step map beside the colours.
        beside = hover(p, 9.5 / 32, 12.5 / 32, got["id"], panel=1)
        assert len(shown["pictures"]) == 2 and beside["readout"] == read
        # A click there pins the probe: v(t) at that voxel over every step, marked on the view.
        page.mouse.down()
        page.mouse.up()
        p.page.wait_for_function("() => window.viewer.probe && window.viewer.probe.pinned")
        probe = p.eval("() => window.viewer.probe")
        assert probe["voxel"] == {"x": vx, "y": vy, "z": vz} and probe["view"] == 0
        curve = [float(series.read_region(t, vz, vy, vx)) for t in range(series.n_steps)]
        assert probe["values"] == pytest.approx(curve)
        text = page.locator("#probe-text").text_content()
        assert text == f"voxel x={vx} y={vy} z={vz} (pinned on the slice) · view 1"
        p.page.wait_for_function(  # the mark on the view, where the voxel projects
            "() => { const m = document.querySelector('#views .view .probe-mark');"
            " return m && getComputedStyle(m).display !== 'none'; }"
        )
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-slice-panel.png"))

        # Larger over the views: drawn again at the size it is shown at, read out the same way.
        page.locator("#slice-large").click()
        p.page.wait_for_function(
            """(after) => { const s = window.viewer.slice, img = document.getElementById(
                 'slice-big-pic'); return s && s.id > after && img.complete
                 && img.getAttribute('src') === s.png && img.naturalWidth === s.size[0]; }""",
            arg=beside["id"],
            timeout=60_000,
        )
        big = p.eval(SHOWN, "slice-big-pic")
        assert big["size"][0] > 2 * shown["size"][0] and big["natural"] == big["size"]
        assert (
            abs(big["shown"][2] - big["size"][0]) <= 2 or abs(big["shown"][3] - big["size"][1]) <= 2
        )
        assert big["grid"] == shown["grid"]
        got = hover(p, 25.5 / 32, 3.5 / 32, big["id"], img="slice-big-pic")
        vx, vy = 25, 31 - 3
        assert got["readout"]["voxel"] == {"x": vx, "y": vy, "z": 20}
        assert got["readout"]["step"] == int(cv.t_index[20, vy, vx])
        assert page.locator("#slice-big-readout").text_content() == got["text"]
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-slice-large.png"))
        page.locator("#slice-big-close").click()
        assert page.locator("#slice-big").is_hidden()
        got = wait_slice(p, "z=20", big["id"])  # drawn again at the side panel's width
        assert abs(got["size"][0] - shown["size"][0]) <= 2

        # An alpha view keeps no step: the panel follows the mode (after its frame) and says so.
        choose(p, "#views .view select.mode", "alpha")
        again = wait_slice(p, "z=20", got["id"])
        assert again["t_index"] is False
        got = hover(p, 0.5, 0.5, again["id"])
        assert got["readout"]["step"] is None
        assert "no winning step" in got["text"] and "no t_index" in got["text"]
        # The panel folded: no outline left on the view.
        page.locator("#slice-panel summary").click()
        p.page.wait_for_function(f"() => ({CUT})().length === 0")  # (toggle fires after)
    finally:
        p.close()  # asserts no page errors
