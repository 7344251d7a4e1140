"""The viewer page in Chromium as a user sees it: the time-opacity sliders follow the shape
chosen, the probe plot and marker follow the window, the camera and the data set, the panels
fill the view area (2x2 for four views) at 1400x900 and 1024x640 and follow the device pixel
ratio, the side panel folds away, the TF curve stays inside its plot when zoomed, labels are
readable on white, a nearly empty view says why, and a slow frame shows a busy indicator.
Over the socket: a frame answering input is drawn within the draw budget and redrawn at the
panel's size once input stops.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os
import time

import pytest

pytest.importorskip("starlette")
playwright_api = pytest.importorskip("playwright.sync_api")

from chronocl.core.tuning import TUNING  # noqa: E402
from chronocl.viewer import frames  # noqa: E402
from chronocl.viewer import worker as worker_module  # noqa: E402

from .viewer_helpers import (  # noqa: E402
    CHROMIUM,
    SETTLED_FRAME,
    Client,
    launch_browser,
    make_stores,
    serving,
)

# Resolves after the page's next animation frame (or 2 s: evaluate has no timeout of its own).
NEXT_ANIMATION_FRAME = (
    "() => new Promise((r) => { requestAnimationFrame(() => r()); setTimeout(r, 2000); })"
)

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    yield from serving(make_stores(tmp_path_factory.mktemp("viewer-page")))


@pytest.fixture(scope="module")
def browser():
    yield from launch_browser()


class Page:
    """One page at a viewport size; `problems` collects the page's script errors."""

    def __init__(self, browser, server, width: int, height: int, dpr: float = 1.0) -> None:
        self.context = browser.new_context(
            viewport={"width": width, "height": height},
            device_scale_factor=dpr,
            bypass_csp=True,  # Playwright's waiting helpers evaluate strings
        )
        self.page = self.context.new_page()
        self.problems: list[str] = []
        self.page.on("pageerror", lambda e: self.problems.append(str(e)))
        self.page.goto(server.url)
        self.page.wait_for_function(
            "() => window.viewer && window.viewer.full >= 1", timeout=60_000
        )
        self.settle()

    def eval(self, js: str, arg=None):
        return self.page.evaluate(js, arg)

    def last(self) -> dict:
        return self.eval("() => window.viewer.last")

    def settle(self, before: dict | None = None) -> dict:
        """Wait for the final frame (full quality, level and size) answering the newest
        request; returns viewer.last. An update the page made is sent on its next animation
        frame: one goes by first, so that an older frame cannot pass for its answer."""
        seq = 0 if before is None else before["seq"]
        self.eval(NEXT_ANIMATION_FRAME)
        self.page.wait_for_function(SETTLED_FRAME, arg=[seq], timeout=60_000)
        return self.last()

    def close(self) -> None:
        assert self.problems == []
        self.context.close()


@pytest.fixture
def open_page(browser, server):
    pages: list[Page] = []

    def make(width=1400, height=900, dpr=1.0) -> Page:
        pages.append(Page(browser, server, width, height, dpr))
        return pages[-1]

    yield make
    for p in pages:
        p.close()


def shots_dir(tmp_path) -> str:
    path = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    os.makedirs(path, exist_ok=True)
    return path


def drag(page, start: dict, end: dict, steps: int = 8) -> None:
    page.mouse.move(start["x"], start["y"])
    page.mouse.down()
    page.mouse.move(end["x"], end["y"], steps=steps)
    page.mouse.up()


def boxes(p: Page) -> dict:
    """Element boxes (CSS px) of the view area, the panels and the controls that must show."""
    return p.eval(
        """() => {
          const r = (el) => { const b = el.getBoundingClientRect();
            return {x: b.left, y: b.top, w: b.width, h: b.height}; };
          return {
            area: r(document.getElementById('views')),
            panels: [...document.querySelectorAll('.view')].map(r),
            inner: [...document.querySelectorAll('.view .view-pic')].map(
              (el) => ({w: el.clientWidth, h: el.clientHeight})),
            pictures: [...document.querySelectorAll('.view .view-pic')].map(r),
            images: [...document.querySelectorAll('.view img')].map(r),
            side: r(document.getElementById('side')),
            controls: [...document.querySelectorAll('#bar button, #bar select, footer button')]
              .map(r),
            viewport: {w: innerWidth, h: innerHeight},
            size: window.viewer.S.state.size,
          };
        }"""
    )


def check_fills(b: dict, n: int, grid: tuple[int, int] | None = None) -> float:
    """Panels inside the view area, not overlapping, covering >= 80 % of it, four views in a
    full grid (2x2, or a row of four where that gives larger pictures), `grid` (columns, rows)
    if given; returns the fraction covered."""
    area = b["area"]
    assert len(b["panels"]) == n
    for q in b["panels"]:
        assert q["x"] >= area["x"] - 0.5 and q["y"] >= area["y"] - 0.5
        assert q["x"] + q["w"] <= area["x"] + area["w"] + 0.5
        assert q["y"] + q["h"] <= area["y"] + area["h"] + 0.5
    covered = sum(q["w"] * q["h"] for q in b["panels"]) / (area["w"] * area["h"])
    assert covered >= 0.8, f"{n} views cover {covered:.0%} of the view area"
    columns = len({round(q["x"]) for q in b["panels"]})
    rows = len({round(q["y"]) for q in b["panels"]})
    if n == 4:
        assert columns * rows == 4
    if grid is not None:
        assert (columns, rows) == grid
    return covered


def set_views(p: Page, n: int) -> dict:
    before = p.last()
    p.page.select_option("#nviews", str(n))
    frame = p.settle(before)
    assert frame["views"] == n
    p.page.wait_for_timeout(300)  # the resize observer's debounce
    return p.settle({"seq": 0})


# -------------------------------------------------------------------- 1: time opacity
def test_time_opacity_sliders_follow_the_shape_chosen(open_page):
    p = open_page(1400, 900)
    disabled = (
        "() => ['t-center','t-width','t-floor'].map(i => document.getElementById(i).disabled)"
    )
    assert p.eval(disabled) == [True, True, True]  # constant reads none of them
    p.page.select_option("#time-alpha", "hat")
    assert p.eval(disabled) == [False, False, False]
    p.page.select_option("#time-alpha", "constant")
    assert p.eval(disabled) == [True, True, True]


# -------------------------------------------------------------------- 2: probe plot
SHADED_COLUMN = """([step]) => {
  // Whether the probe plot shades the column of `step` (the window's band, orange, faint).
  const c = document.getElementById('probe');
  const r = c.getBoundingClientRect(), dpr = c.width / r.width;
  const T = window.viewer.probe.values.length;
  const inset = step === 0 ? 3 : step === T - 1 ? -3 : 0; // off the plot's frame line
  const x = Math.round((40 + (step / (T - 1)) * (r.width - 46) + inset) * dpr);
  const top = Math.round(10 * dpr), bottom = Math.round((r.height - 18) * dpr);
  const px = c.getContext('2d').getImageData(x, top, 1, bottom - top).data;
  let shade = 0;
  for (let k = 0; k < px.length; k += 4) {
    const [red, g, b, a] = [px[k], px[k + 1], px[k + 2], px[k + 3]];
    if (a > 15 && a < 90 && red > b && g > b) shade += 1;
  }
  return shade / (px.length / 4) > 0.5;
}"""

MARK = """() => [...document.querySelectorAll('.probe-mark')].map(m =>
  m.style.display === 'none' || !m.style.display ? null : [m.style.left, m.style.top])"""


def test_probe_plot_and_marker_follow_window_camera_and_data_set(open_page):
    p = open_page(1400, 900)
    page = p.page
    box = page.locator(".view img").first.bounding_box()
    page.mouse.click(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.5)
    page.wait_for_function(
        "() => window.viewer.probe && window.viewer.probe.values", timeout=60_000
    )
    assert p.eval("() => window.viewer.S.state.window") == {"t0": 1, "t1": 11, "stride": 1}
    assert p.eval(SHADED_COLUMN, [10]) and not p.eval(SHADED_COLUMN, [0])
    mark = p.eval(MARK)[0]
    assert mark is not None
    # The marker sits on the voxel found: its projection is (nearly) the pixel clicked.
    assert all(abs(float(v.rstrip("%")) - 50) < 4 for v in mark)

    # The window slides (as play does): the shaded band follows it.
    before = p.last()
    page.keyboard.press("ArrowLeft")
    p.settle(before)
    assert p.eval("() => window.viewer.S.state.window")["t0"] == 0
    assert p.eval(SHADED_COLUMN, [0]) and not p.eval(SHADED_COLUMN, [10])

    # Orbit: the marker follows the voxel instead of staying at the same screen spot.
    before = p.last()
    c = {"x": box["x"] + box["width"] / 2, "y": box["y"] + box["height"] / 2}
    drag(page, {"x": c["x"] - 100, "y": c["y"]}, {"x": c["x"] + 60, "y": c["y"] + 40})
    p.settle(before)
    orbited = p.eval(MARK)[0]
    assert orbited != mark

    # A shift-drag around the feature from empty corners probes the box it spans.
    page.keyboard.down("Shift")
    page.mouse.move(box["x"] + box["width"] * 0.04, box["y"] + box["height"] * 0.04)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.96, box["y"] + box["height"] * 0.96, steps=6)
    page.mouse.up()
    page.keyboard.up("Shift")
    page.wait_for_function(
        "() => window.viewer.probe && window.viewer.probe.box && window.viewer.probe.values",
        timeout=60_000,
    )
    assert page.inner_text("#probe-text").startswith("box x ")

    # Another data set: the old curve is not drawn against the new series.
    before = p.last()
    page.select_option("#dataset", "1")
    p.settle(before)
    assert p.eval("() => window.viewer.S.info.shape.t") == 10
    blank = """() => { const c = document.getElementById('probe');
      return c.getContext('2d').getImageData(0, 0, c.width, c.height).data.every(v => v === 0); }"""
    assert p.eval(blank)
    assert p.eval(MARK) == [None]


# -------------------------------------------------------------------- 3, 4: layout
@pytest.mark.parametrize("width,height", [(1400, 900), (1024, 640)])
def test_panels_fill_the_view_area_at_1_2_and_4_views(open_page, tmp_path, width, height):
    p = open_page(width, height)
    shots = shots_dir(tmp_path)
    for n in (1, 2, 4):
        if n > 1:
            set_views(p, n)
        b = boxes(p)
        # Nothing is cut off: the side panel and every header and footer control show.
        vw, vh = b["viewport"]["w"], b["viewport"]["h"]
        assert b["side"]["x"] + b["side"]["w"] <= vw + 0.5
        for c in b["controls"]:
            assert c["x"] >= 0 and c["x"] + c["w"] <= vw + 0.5 and c["y"] + c["h"] <= vh + 0.5
        check_fills(b, n, (2, 2) if n == 4 else None)
        # The image fills its panel's picture box, between the panel's bands (the render
        # follows the box's shape), and that box takes most of the panel.
        for img, pic, q in zip(b["images"], b["pictures"], b["panels"], strict=True):
            assert img == pic
            assert pic["w"] >= q["w"] - 4 and pic["h"] * pic["w"] >= 0.5 * q["h"] * q["w"]
        w, h = b["size"]
        assert abs(w / h - b["pictures"][0]["w"] / b["pictures"][0]["h"]) < 0.05
        p.page.screenshot(path=os.path.join(shots, f"viewer-{width}x{height}-{n}views.png"))


def test_side_panel_folds_and_render_follows_device_pixels(open_page, tmp_path):
    p = open_page(1024, 640, dpr=2.0)
    set_views(p, 4)
    b = boxes(p)
    check_fills(b, 4)
    q = b["inner"][0]  # the picture's box
    w, h = b["size"]
    # Device pixels of the picture (2x its CSS size), the longest side within the server's cap.
    cap = p.eval("() => window.viewer.S.choices.limits.max_panel")
    scale = min(2.0, cap / max(q["w"], q["h"]))
    assert abs(w - q["w"] * scale) <= 2 and abs(h - q["h"] * scale) <= 2
    assert w > q["w"] * 1.5  # more than the CSS size at this ratio

    before = p.last()
    p.page.click("#side-toggle")
    p.settle(before)
    p.page.wait_for_timeout(300)
    p.settle({"seq": 0})
    folded = boxes(p)
    assert folded["side"]["w"] == 0
    assert folded["area"]["w"] > b["area"]["w"] + 250
    check_fills(folded, 4)
    # Larger pictures (a row of four where that suits them better), larger renders.
    assert min(folded["size"]) > min(w, h) and folded["size"][0] * folded["size"][1] > w * h
    p.page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-1024x640-folded-dpr2.png"))
    p.page.click("#side-toggle")
    p.page.wait_for_timeout(300)
    assert boxes(p)["side"]["w"] > 200


# -------------------------------------------------------------------- 5: TF editor zoom
def test_tf_curve_stays_inside_the_plot_when_zoomed(open_page):
    p = open_page(1400, 900)
    page = p.page
    span = p.eval("() => [window.viewer.S.info.vmin, window.viewer.S.info.vmax]")
    value = lambda u: span[0] + u * (span[1] - span[0])  # noqa: E731
    # Zoom between the points at u = 0.2 and 0.55: the segment joining them crosses the plot.
    page.fill("#zoom-lo", str(value(0.3)))
    page.dispatch_event("#zoom-lo", "change")
    page.fill("#zoom-hi", str(value(0.4)))
    page.dispatch_event("#zoom-hi", "change")
    assert p.eval("() => window.viewer.S.zoom[0]") > 0.29
    outside = p.eval(
        """() => {
          // Curve-coloured (orange) pixels left and right of the plot area (6 px margins).
          const c = document.getElementById('tf');
          const dpr = c.width / c.getBoundingClientRect().width;
          const ctx = c.getContext('2d');
          const h = Math.round(c.height - 20 * dpr), m = Math.floor(5 * dpr);
          let n = 0;
          for (const x0 of [0, c.width - m]) {
            const px = ctx.getImageData(x0, 0, m, h).data;
            for (let k = 0; k < px.length; k += 4)
              if (px[k + 3] > 60 && px[k] > 150 && px[k + 1] > 90 && px[k + 2] < 110) n += 1;
          }
          return n;
        }"""
    )
    assert outside == 0


# -------------------------------------------------------------------- 6: feedback
def test_labels_read_on_white_and_a_nearly_empty_view_says_why(open_page, tmp_path):
    p = open_page(1400, 900)
    shots = shots_dir(tmp_path)
    page = p.page
    before = p.last()
    page.select_option("#background", "white")
    p.settle(before)
    style = p.eval(
        """() => { const s = getComputedStyle(document.querySelector('.view-label'));
                   return [s.color, s.backgroundColor]; }"""
    )
    rgba = lambda s: [float(v) for v in s[s.index("(") + 1 : -1].split(",")]  # noqa: E731
    fg, bg = rgba(style[0]), rgba(style[1])
    assert len(bg) == 4 and bg[3] >= 0.5  # the label has its own backdrop over the image

    def lum(c):
        f = [v / 255 for v in c[:3]]
        f = [v / 12.92 if v <= 0.03928 else ((v + 0.055) / 1.055) ** 2.4 for v in f]
        return 0.2126 * f[0] + 0.7152 * f[1] + 0.0722 * f[2]

    # The backdrop over white, against the text: WCAG contrast of at least 4.5.
    over = [bg[3] * v + (1 - bg[3]) * 255 for v in bg[:3]]
    hi, lo = sorted([lum(fg), lum(over)], reverse=True)
    assert (hi + 0.05) / (lo + 0.05) >= 4.5
    page.screenshot(path=os.path.join(shots, "viewer-white-background.png"))

    before = p.last()
    page.select_option("#background", "black")
    p.settle(before)
    note = '.view[data-i="0"] .view-note'
    assert page.locator(note).count() == 0 or not page.locator(note).is_visible()
    before = p.last()
    page.select_option('.view[data-i="0"] select.mode', "min")
    p.settle(before)
    assert page.locator(note).is_visible()
    text = page.inner_text(note)
    assert "min" in text and "transfer function" in text
    page.screenshot(path=os.path.join(shots, "viewer-min-note.png"))
    before = p.last()
    page.select_option('.view[data-i="0"] select.mode', "alpha")
    p.settle(before)
    assert not page.locator(note).is_visible()


def test_a_slow_frame_shows_a_busy_indicator(open_page, monkeypatch, tmp_path):
    render = worker_module.ClientWorker._render

    def slow(self, state, rid):
        if state.views[0][0] == "mean":  # as a first use's kernel build stalls the frame
            time.sleep(1.5)
        render(self, state, rid)

    p = open_page(1400, 900)
    monkeypatch.setattr(worker_module.ClientWorker, "_render", slow)
    busy = p.page.locator("#busy")
    assert not busy.is_visible()
    before = p.last()
    p.page.select_option('.view[data-i="0"] select.mode', "mean")
    busy.wait_for(state="visible", timeout=5_000)
    assert "working" in busy.inner_text()
    p.page.screenshot(path=os.path.join(shots_dir(tmp_path), "viewer-busy.png"))
    p.settle(before)
    assert not busy.is_visible()


# -------------------------------------------------------------------- draw budget
def test_render_size_keeps_the_aspect_within_the_budget():
    assert frames.render_size((512, 512), 1) == (512, 512)
    w, h = frames.render_size((1024, 733), 4)
    assert 4 * w * h <= TUNING.pixel_budget and abs(w / h - 1024 / 733) < 0.01
    assert frames.render_size((1024, 733), 1, 0.5) == (512, 366)
    budget = frames.DrawBudget(target_ms=80, floor=100, cap=10_000)
    assert budget.pixels() == 10_000  # nothing measured yet
    budget.record(80.0, 4000)  # 0.02 ms a pixel: 4000 pixels in 80 ms
    assert budget.pixels() == 4000
    budget.record(1e6, 4000)  # very slow: the floor
    assert budget.pixels() == 100
    sharp = frames.DrawBudget(target_ms=80, sharp_ms=150, cap=10**6)
    sharp.record(1.0, 1000)  # 1 ms a 1000 pixels: 80 000 in 80 ms, 150 000 in 150
    assert sharp.pixels() == 80_000 and sharp.pixels(sharp=True) == 150_000
    # A sharp frame predicted a little over its target is drawn whole (no redraw to follow)
    assert sharp.pixels(sharp=True, full=220_000) == 10**6  # 220 ms <= 1.5 x 150
    assert sharp.pixels(sharp=True, full=230_000) == 150_000  # 230 ms: reduced
    assert sharp.pixels(full=100_000) == 80_000  # a frame answering input: its own target


def test_a_frame_a_little_under_full_size_is_redrawn_too(server, monkeypatch):
    """A frame drawn 4 % smaller than its panel is not final: the settled view is always the
    same full-size frame (a slightly smaller one used to count as final)."""
    full = frames.render_size((1024, 733), 1)
    cap = int(0.96 * full[0] * full[1])
    monkeypatch.setattr(worker_module, "DrawBudget", lambda: frames.DrawBudget(cap=cap))
    monkeypatch.setattr(frames.DrawBudget, "record", lambda self, ms, pixels: None)
    client = Client(server)
    try:
        client.open(0, size=(1024, 733))
        rid = client.send({"type": "update", "threshold": 0.1})
        _, first, _ = client.frame_for(rid)
        assert first["reduced"] and first["refining"]
        _, final, _ = client.frame_for(rid)
        assert not final["reduced"] and not final["refining"]
        assert (final["views"][0]["width"], final["views"][0]["height"]) == full
    finally:
        client.close()


def test_a_frame_over_the_draw_budget_is_reduced_then_redrawn_in_full(server, monkeypatch):
    budget = frames.DrawBudget(target_ms=1.0, sharp_ms=1.0)  # every frame over its budget
    monkeypatch.setattr(worker_module, "DrawBudget", lambda: budget)
    client = Client(server)
    try:
        client.open(0, size=(1024, 733))  # a frame drawn: the draw budget has a measurement
        rid = client.send({"type": "update", "threshold": 0.1})
        _, fast, _ = client.frame_for(rid)
        full = frames.render_size((1024, 733), 1)
        w, h = fast["views"][0]["width"], fast["views"][0]["height"]
        assert fast["reduced"] and fast["refining"]
        assert w * h <= TUNING.min_pixels * 1.01 and abs(w / h - 1024 / 733) < 0.02
        _, final, _ = client.frame_for(rid)  # after a short idle, the same state in full
        assert final["seq"] > fast["seq"] and not final["reduced"] and not final["refining"]
        assert (final["views"][0]["width"], final["views"][0]["height"]) == full
    finally:
        client.close()
