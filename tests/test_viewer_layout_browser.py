"""The viewer page at users' sizes in Chromium, with four parallel views: at 1024x700 and
1400x900 nothing but the picture lies on a panel's picture (no caption, menu, legend, axes,
camera tool, busy indicator or button), each legend takes under a third of its panel, the
header keeps undo and redo together and a long data set name on its row, and the menus show
their labels whole. In the data TF editor, a colour-map preset leaves only the opacity curve's
own points as handles (the colours follow the map through its stops, which are not handles),
the points sent stay a valid data TF coloured by the map, and that holds after a drag, an undo
and a reload of the page.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from chronocl.core.colormaps import colormap_stops
from chronocl.core.tf import DataTF
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.viewer import worker as worker_module

from .test_viewer_page_browser import Page, browser, set_views, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, start_server

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

# A name as long as a simulation run's: it must not push the header onto a third row.
LONG_NAME = "phiflow_smoke_plume_inflow_64x96x56_48_steps_run_0003"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    root = tmp_path_factory.mktemp("viewer-layout")
    data = np.stack(list(synthetic.steps("vortex", 12, (32, 32, 32))))
    path = root / f"{LONG_NAME}.zarr"
    TimeSeries.from_array(data, source=LONG_NAME).save(path)
    srv = start_server([path])
    yield srv
    srv.stop()


# Every visible element that overlaps a panel's picture (the <img> the frame is drawn in), other
# than the picture's own box and what is in it (the probe's marks, the clip outline, an empty
# view's note) and the boxes that hold the panels; the legends' and pictures' boxes.
OVERLAPS = """() => {
  const box = (el) => { const r = el.getBoundingClientRect();
    return {x: r.left, y: r.top, w: r.width, h: r.height}; };
  const name = (el) => el.tagName.toLowerCase() + (el.id ? '#' + el.id : '') +
    (typeof el.className === 'string' && el.className ? '.' + el.className.split(' ')[0] : '');
  const pics = [...document.querySelectorAll('#views .view-pic img')];
  const holders = new Set();
  for (const img of pics) for (let e = img.parentElement; e; e = e.parentElement) holders.add(e);
  const hits = [];
  for (const el of document.querySelectorAll('body *')) {
    if (holders.has(el) || el.closest('.view-pic')) continue;
    if (!el.checkVisibility({opacityProperty: true, visibilityProperty: true})) continue;
    const a = box(el);
    if (a.w < 1 || a.h < 1) continue;
    pics.forEach((img, k) => {
      const b = box(img);
      const ix = Math.min(a.x + a.w, b.x + b.w) - Math.max(a.x, b.x);
      const iy = Math.min(a.y + a.h, b.y + b.h) - Math.max(a.y, b.y);
      if (ix > 0.5 && iy > 0.5)
        hits.push(`${name(el)} over picture ${k} (${ix.toFixed(0)}x${iy.toFixed(0)} px)`);
    });
  }
  const visible = (el) => el.checkVisibility({visibilityProperty: true});
  return {
    hits,
    pictures: pics.map(box),
    panels: [...document.querySelectorAll('#views .view')].map(box),
    legends: [...document.querySelectorAll('#views .view canvas.legend')].map(
      (c) => (visible(c) ? box(c) : null)),
    colorbars: [...document.querySelectorAll('#views .view canvas.colorbar')].map(
      (c) => (visible(c) ? box(c) : null)),
    size: window.viewer.S.state.size,
  };
}"""

# Buttons and menus of the header: the top of undo and redo, the header's rows, and any of its
# items outside the window; the menus (header and side panel) whose longest entry is cut.
HEADER_AND_MENUS = """() => {
  const top = (id) => Math.round(document.getElementById(id).getBoundingClientRect().top);
  const rows = [...document.querySelectorAll('#bar .bar-row')].map(
    (r) => Math.round(r.getBoundingClientRect().height));
  const outside = [...document.querySelectorAll('#bar button, #bar select, #bar label')]
    .filter((el) => { const r = el.getBoundingClientRect();
      return r.left < 0 || r.right > innerWidth + 0.5; })
    .map((el) => el.id || el.textContent.trim());
  const ctx = document.createElement('canvas').getContext('2d');
  const cut = [];
  for (const s of document.querySelectorAll('#bar select, #side select')) {
    if (!s.checkVisibility() || s.id === 'dataset') continue;
    const cs = getComputedStyle(s);
    ctx.font = `${cs.fontWeight} ${cs.fontSize} ${cs.fontFamily}`;
    // The room for the text: the box less its padding, border and the menu's arrow (20 px).
    const room = s.clientWidth - parseFloat(cs.paddingLeft) - parseFloat(cs.paddingRight) - 20;
    for (const o of s.options)
      if (!o.hidden && ctx.measureText(o.text).width > room) cut.push(`${s.id}: ${o.text}`);
  }
  return {undo: top('undo'), redo: top('redo'), rows, outside, cut};
}"""


def overlap(a: dict, b: dict) -> float:
    ix = min(a["x"] + a["w"], b["x"] + b["w"]) - max(a["x"], b["x"])
    iy = min(a["y"] + a["h"], b["y"] + b["h"]) - max(a["y"], b["y"])
    return max(0.0, ix) * max(0.0, iy)


@pytest.mark.parametrize("width,height", [(1024, 700), (1400, 900)])
def test_nothing_lies_on_a_picture_with_four_views(
    browser,  # noqa: F811
    server,
    monkeypatch,
    tmp_path,
    width,
    height,
):
    render = worker_module.ClientWorker._render

    def slow(self, state, rid):
        if state.views[0][0] == "mean":  # a slow frame: the busy indicator shows
            time.sleep(2.0)
        render(self, state, rid)

    p = Page(browser, server, width, height)
    try:
        page = p.page
        shots = shots_dir(tmp_path)
        set_views(p, 4)
        got = p.eval(OVERLAPS)
        assert got["hits"] == [], got["hits"]
        for pic, panel, legend in zip(got["pictures"], got["panels"], got["legends"], strict=True):
            area = panel["w"] * panel["h"]
            # The legend shows, under its picture, in under a third of its panel.
            assert legend is not None and legend["w"] * legend["h"] < area / 3
            assert legend["y"] >= pic["y"] + pic["h"] - 0.5
            # The picture keeps most of its panel, and the render has its shape.
            assert pic["w"] * pic["h"] > 0.5 * area
            assert abs(got["size"][0] / got["size"][1] - pic["w"] / pic["h"]) < 0.05
        # The camera tools are in the header, clear of every panel.
        tools = page.locator("#camera-tools").bounding_box()
        tools = {"x": tools["x"], "y": tools["y"], "w": tools["width"], "h": tools["height"]}
        assert all(overlap(tools, q) == 0 for q in got["panels"])
        page.screenshot(path=os.path.join(shots, f"layout-{width}x{height}-4views.png"))

        # The header: two rows of one line each (a long data set name included), undo and redo
        # side by side, nothing outside the window; no menu's entry cut short.
        bar = p.eval(HEADER_AND_MENUS)
        assert LONG_NAME in page.locator("#dataset option").first.inner_text()
        assert len(bar["rows"]) == 2 and all(h <= 34 for h in bar["rows"]), bar["rows"]
        assert bar["undo"] == bar["redo"] and bar["outside"] == []
        assert bar["cut"] == [], bar["cut"]

        # A slow frame: the busy indicator shows, in the header, over no picture; the views do
        # not move when it shows.
        monkeypatch.setattr(worker_module.ClientWorker, "_render", slow)
        busy = page.locator("#busy")
        before = p.last()
        page.select_option('.view[data-i="0"] select.mode', "mean")
        busy.wait_for(state="visible", timeout=5_000)
        assert "working" in busy.inner_text()
        during = p.eval(OVERLAPS)
        assert during["hits"] == [], during["hits"]
        assert during["pictures"] == got["pictures"]
        page.screenshot(path=os.path.join(shots, f"layout-{width}x{height}-busy.png"))
        p.settle(before)
        monkeypatch.setattr(worker_module.ClientWorker, "_render", render)

        # A colour map: the data colour bar joins the time legend in the foot band, clear of
        # the pictures, which keep their size; the two take under a third of the panel.
        before = p.last()
        page.select_option("#tf-colormap", "viridis")
        p.settle(before)
        page.wait_for_function(
            "() => document.querySelector('#views .view canvas.colorbar').checkVisibility()"
        )
        mapped = p.eval(OVERLAPS)
        assert mapped["hits"] == [], mapped["hits"]
        assert mapped["pictures"] == got["pictures"]
        for panel, legend, bar in zip(
            mapped["panels"], mapped["legends"], mapped["colorbars"], strict=True
        ):
            assert legend is not None and bar is not None
            area = legend["w"] * legend["h"] + bar["w"] * bar["h"]
            assert area < panel["w"] * panel["h"] / 3
        page.screenshot(path=os.path.join(shots, f"layout-{width}x{height}-colour-map.png"))

        # Legend and axes hidden: the pictures take their band, and the render follows.
        before = p.last()
        page.uncheck("#legend-on")
        page.uncheck("#triad-on")
        page.wait_for_function(
            "([h]) => document.querySelector('#views .view-pic').clientHeight > h + 40",
            arg=[got["pictures"][0]["h"]],
        )
        p.settle(before)
        page.wait_for_timeout(300)  # the resize observer's debounce
        p.settle({"seq": 0})
        bare = p.eval(OVERLAPS)
        assert bare["hits"] == [], bare["hits"]
        assert bare["size"][1] > got["size"][1]
        page.check("#legend-on")
        page.check("#triad-on")
    finally:
        p.close()


def test_one_view_at_1024x700_has_nothing_on_its_picture(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1024, 700)
    try:
        got = p.eval(OVERLAPS)
        assert len(got["pictures"]) == 1 and got["hits"] == [], got["hits"]
        p.page.screenshot(path=os.path.join(shots_dir(tmp_path), "layout-1024x700-1view.png"))
    finally:
        p.close()


# The TF editor's points as drawn: for each, whether its centre pixel has the point's own
# colour (a handle is a disc of it; elsewhere the orange curve runs through the point) and its
# distance (CSS px) to the nearest handle but itself (a point inside a handle's disc is hidden).
DRAWN = """() => {
  const c = document.getElementById('tf');
  const r = c.getBoundingClientRect();
  const dpr = c.width / r.width;
  const ctx = c.getContext('2d');
  const pts = window.viewer.S.state.data_tf.points;
  const handles = window.viewer.tfHandles();
  const at = pts.map((_, i) => window.viewer.tfPointAt(i));
  return pts.map((p, i) => {
    const x = Math.round((at[i].x - r.left) * dpr), y = Math.round((at[i].y - r.top) * dpr);
    const px = ctx.getImageData(x, y, 1, 1).data;
    const d = Math.hypot(px[0] - p[1] * 255, px[1] - p[2] * 255, px[2] - p[3] * 255);
    const near = Math.min(Infinity, ...handles.filter((h) => h !== i)
      .map((h) => Math.hypot(at[h].x - at[i].x, at[h].y - at[i].y)));
    return {drawn: d < 30, near};
  });
}"""


def drawn_handles(p: Page, handles: list[int]) -> None:
    """Every handle is drawn, and no other point clear of the handles' discs is."""
    drawn = p.eval(DRAWN)
    assert all(drawn[i]["drawn"] for i in handles)
    clear = [i for i, d in enumerate(drawn) if i not in handles and d["near"] > 8]
    assert len(clear) >= 20 and not any(drawn[i]["drawn"] for i in clear)


def coloured_by(points: list, name: str) -> bool:
    """Whether every point has map `name`'s colour at its position."""
    stops = np.asarray(colormap_stops(name))
    pts = np.asarray(points)
    want = np.stack([np.interp(pts[:, 0], stops[:, 0], stops[:, j]) for j in (1, 2, 3)], -1)
    return bool(np.abs(pts[:, 1:4] - want).max() < 2e-3)


def test_a_colour_map_leaves_the_opacity_points_as_the_only_handles(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        shots = shots_dir(tmp_path)
        own = p.eval("() => window.viewer.S.state.data_tf.points")
        assert p.eval("() => window.viewer.tfHandles()") == list(range(len(own)))
        before = p.last()
        page.select_option("#tf-colormap", "viridis")
        after = p.settle(before)
        assert after["digest"] != before["digest"]
        points = p.eval("() => window.viewer.S.state.data_tf.points")
        # What the server gets: the TF with the map's stops, as DataTF.with_colormap gives it.
        want = DataTF(points=[tuple(q) for q in own]).with_colormap("viridis").points
        assert len(points) == len(want) >= 33
        for g, w in zip(points, want, strict=True):
            assert g == pytest.approx(list(w), abs=1e-9)
        # What the user sees: the curve's own points as handles, each drawn; no stop drawn.
        handles = p.eval("() => window.viewer.tfHandles()")
        assert len(handles) <= 8 and [points[i][0] for i in handles] == [q[0] for q in own]
        drawn_handles(p, handles)
        assert page.locator("#tf-colormap").input_value() == "viridis"
        assert page.locator("#point-color").is_disabled()  # the colours follow the map
        page.locator("#tf").screenshot(path=os.path.join(shots, "tf-viridis-handles.png"))

        # Drag the second handle up and right: still the same handles, the curve goes through
        # the new place, the colours still follow the map, the TF stays valid.
        at = p.eval(f"() => window.viewer.tfPointAt({handles[1]})")
        before = p.last()
        page.mouse.move(at["x"], at["y"])
        page.mouse.down()
        page.mouse.move(at["x"] + 40, at["y"] - 40, steps=6)
        page.mouse.up()
        p.settle(before)
        dragged = p.eval("() => window.viewer.S.state.data_tf.points")
        moved = dragged[p.eval("() => window.viewer.S.selectedPoint")]
        assert moved[0] > own[1][0] + 0.02 and moved[4] > own[1][4] + 0.05
        handles2 = p.eval("() => window.viewer.tfHandles()")
        assert len(handles2) == len(handles)
        drawn_handles(p, handles2)
        assert coloured_by(dragged, "viridis")
        DataTF(points=[tuple(q) for q in dragged])  # a valid data TF
        # The stops between the handles lie on the handles' curve (opacity follows them).
        hs = np.asarray([dragged[i] for i in handles2])
        d = np.asarray(dragged)
        assert np.abs(d[:, 4] - np.interp(d[:, 0], hs[:, 0], hs[:, 4])).max() < 1e-9
        page.locator("#tf").screenshot(path=os.path.join(shots, "tf-viridis-dragged.png"))

        # The end handles keep their place under a map (the map spans the range): only their
        # opacity moves.
        end = handles2[-1]
        at = p.eval(f"() => window.viewer.tfPointAt({end})")
        before = p.last()
        page.mouse.move(at["x"], at["y"])
        page.mouse.down()
        page.mouse.move(at["x"] - 60, at["y"] + 30, steps=6)
        page.mouse.up()
        p.settle(before)
        last = p.eval("() => window.viewer.S.state.data_tf.points.at(-1)")
        assert last[0] == 1.0 and last[4] < dragged[-1][4] - 0.05
        assert len(p.eval("() => window.viewer.tfHandles()")) == len(handles)

        # Undo, and a reload of the page (the address keeps the state): the handles are read
        # off the points again, the same.
        before = p.last()
        page.keyboard.press("Control+z")
        p.settle(before)
        assert p.eval("() => window.viewer.tfHandles()") == handles2
        page.reload()
        page.wait_for_function("() => window.viewer && window.viewer.full >= 1", timeout=60_000)
        p.settle({"seq": 0})
        reloaded = p.eval("() => window.viewer.S.state.data_tf.points")
        np.testing.assert_allclose(np.asarray(reloaded), np.asarray(dragged), atol=1e-9)
        assert p.eval("() => window.viewer.tfHandles()") == handles2
        assert page.locator("#tf-colormap").input_value() == "viridis"

        # Another map: the same handles, the new map's colours.
        before = p.last()
        page.select_option("#tf-colormap", "magma")
        p.settle(before)
        magma = p.eval("() => window.viewer.S.state.data_tf.points")
        assert coloured_by(magma, "magma")
        assert len(p.eval("() => window.viewer.tfHandles()")) == len(handles)

        # None: the handles alone stay, each with the colour the map gave it.
        before = p.last()
        page.select_option("#tf-colormap", "")
        p.settle(before)
        plain = p.eval("() => window.viewer.S.state.data_tf.points")
        assert len(plain) == len(handles) and coloured_by(plain, "magma")
        assert p.eval("() => window.viewer.tfHandles()") == list(range(len(plain)))
        assert not page.locator("#point-color").is_disabled()
    finally:
        p.close()
