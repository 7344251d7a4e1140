"""What the viewer page writes beside the pictures, in Chromium (issue 49): the timeline's
ticks at nice steps, times or dates, in a row of their own that no cell, residency bar or
brush draws into, never overlapping at any width; its time-colour cells a row per view where
views draw their own (window or time TF), the selected view's bright; a new view copies the
selected view's mode and order (the transfer functions are every view's), and the page's
address keeps it; the data set menu shows a long name and its shape whole at 1400 and 1000 px;
the fit's note under the TF editor says when the curve is no longer fitted to the mode and
window shown; a nearly empty view's note lies in a strip at the picture's foot, clear of its
middle.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import itertools
import os
import re

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.server import ViewerServer

from .test_viewer_page_browser import Page, browser, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

LONG = "vortex-512-20-float32"  # the name in the report, over a volume of 96 x 32 x 24
SECONDS, HOURLY, CUBE = 1, 2, 3  # the other data sets' indices


@pytest.fixture(scope="module")
def server():
    steps = lambda n, shape: np.stack(list(synthetic.steps("vortex", n, shape)))  # noqa: E731
    small = steps(240, (8, 8, 8))
    hours = [f"2024-01-{1 + (6 + k) // 24:02d}T{(6 + k) % 24:02d}:00:00" for k in range(48)]
    datasets = [
        Dataset(LONG, TimeSeries.from_array(steps(20, (24, 32, 96)))),
        Dataset(
            "seconds",
            TimeSeries.from_array(small, times=[0.25 * k for k in range(240)], time_unit="s"),
        ),
        Dataset("hourly", TimeSeries.from_array(small[:48], times=hours)),
        Dataset("vortex", TimeSeries.from_array(steps(12, (32, 32, 32)))),
    ]
    srv = ViewerServer(datasets=datasets)
    srv.start()
    yield srv
    srv.stop()


def open_dataset(p: Page, index: int) -> dict:
    p.page.select_option("#dataset", str(index))
    p.page.wait_for_function(
        f"() => window.viewer.S.info && window.viewer.S.info.index === {index}"
    )
    return p.settle({"seq": 0})


def act(p: Page, do) -> dict:
    """Do something that sends an update; the settled frame answering it."""
    before = p.last()
    do()
    return p.settle(before)


# ------------------------------------------------------------------------- 1: timeline ticks
# The timeline's layout as drawn (CSS px of the canvas), and per row of the axis (below
# axisTop) whether a pixel that is drawn there has colour (a cell's, the residency bar's, the
# brush's): the axis row holds grey marks and labels only.
TIMELINE = """() => {
  const c = document.getElementById('timeline');
  const L = window.viewer.timelineLayout;
  const k = c.width / L.width;
  const ctx = c.getContext('2d');
  const y0 = Math.ceil((L.axisTop + 0.5) * k);
  const px = ctx.getImageData(0, y0, c.width, c.height - y0).data;
  let coloured = 0, drawn = 0;
  for (let i = 0; i < px.length; i += 4) {
    if (px[i + 3] < 48) continue; // (faint anti-aliased edges: their colour is rounding)
    drawn += 1;
    const [r, g, b] = [px[i], px[i + 1], px[i + 2]];
    if (Math.max(r, g, b) - Math.min(r, g, b) > 24) coloured += 1;
  }
  // Ink inside each label's box: the label is drawn where it says.
  const ink = L.labels.map((l) => {
    const d = ctx.getImageData(Math.floor(l.x * k), Math.floor(l.y * k),
      Math.max(1, Math.ceil(l.w * k)), Math.max(1, Math.ceil(l.h * k))).data;
    let n = 0;
    for (let i = 3; i < d.length; i += 4) if (d[i] > 64) n += 1;
    return n;
  });
  return {...L, coloured, drawn, ink, ticks: c.dataset.ticks.split('|')};
}"""


def intersects(a: dict, b: dict) -> bool:
    return (
        a["x"] < b["x"] + b["w"]
        and b["x"] < a["x"] + a["w"]
        and a["y"] < b["y"] + b["h"]
        and b["y"] < a["y"] + a["h"]
    )


def check_timeline(t: dict) -> None:
    """Labels in the axis row, inside the canvas, apart from each other and from every cell and
    the residency bar, drawn where they say; nothing coloured in their row."""
    labels = t["labels"]
    assert labels, t
    for label in labels:
        assert label["x"] >= 0 and label["x"] + label["w"] <= t["width"] + 0.5, label
        assert label["y"] >= t["axisTop"] and label["y"] + label["h"] <= t["height"], label
        for box in [*t["cells"], t["residency"]]:
            assert not intersects(label, box), (label, box)
    for a, b in itertools.pairwise(labels):
        assert b["x"] >= a["x"] + a["w"] + 4, (a, b)  # apart, left to right
    assert all(n > 0 for n in t["ink"]), t["ink"]
    assert t["drawn"] > 0 and t["coloured"] == 0, t


def nice(step: float) -> bool:
    mantissa = step / 10 ** np.floor(np.log10(step) + 1e-9)
    return any(abs(mantissa - m) < 1e-6 for m in (1, 2, 5))


def check_nice(ticks: list[str], unit: str = "") -> list[float]:
    """Tick values (the texts less `unit`) a nice step apart, each a multiple of it."""
    values = [float(t.removesuffix(unit)) for t in ticks]
    if len(values) > 1:
        step = values[1] - values[0]
        assert np.allclose(np.diff(values), step) and nice(step), ticks
        assert all(v / step == pytest.approx(round(v / step)) for v in values), ticks
    return values


def redraw_at(p: Page, width: int | None) -> dict:
    """The timeline drawn `width` CSS px wide (None: as the page lays it out)."""
    p.eval(
        """(w) => { const c = document.getElementById('timeline');
                    c.style.flex = w === null ? '' : 'none';
                    c.style.width = w === null ? '' : `${w}px`;
                    window.dispatchEvent(new Event('resize')); }""",
        width,
    )
    p.page.wait_for_function(
        "(w) => { const L = window.viewer.timelineLayout;"
        " const c = document.getElementById('timeline');"
        " return L && Math.abs(L.width - c.getBoundingClientRect().width) < 0.5"
        " && (w === null || Math.abs(L.width - w) < 0.5); }",
        arg=width,
    )
    return p.eval(TIMELINE)


def test_timeline_ticks_are_nice_apart_and_clear_of_the_cells(browser, server, tmp_path):  # noqa: F811
    shots = shots_dir(tmp_path)
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        # 20 steps at 1400 px: every step labelled, 19 too, in the row under the cells.
        t = p.eval(TIMELINE)
        check_timeline(t)
        assert t["axis"] == "step" and t["ticks"] == [str(s) for s in range(20)]
        page.locator("#timeline-row").screenshot(
            path=os.path.join(shots, "timeline-steps-1400.png")
        )
        # Narrower: fewer labels, at nice steps, still apart (as narrow as 60 px).
        counts = []
        for width in (900, 500, 300, 200, 120, 60):
            t = redraw_at(p, width)
            check_timeline(t)
            check_nice(t["ticks"])
            counts.append(len(t["ticks"]))
        assert counts == sorted(counts, reverse=True) and 1 <= counts[-1] < counts[0] <= 20
        redraw_at(p, None)

        # Numeric times with a unit (240 steps of 0.25 s): nice times, the unit on each.
        open_dataset(p, SECONDS)
        for width in (1400, 1000):
            page.set_viewport_size({"width": width, "height": 900})
            t = redraw_at(p, None)
            check_timeline(t)
            assert t["axis"] == "number" and all(x.endswith(" s") for x in t["ticks"])
            values = check_nice(t["ticks"], " s")
            assert values[0] == 0 and values[-1] >= 50 and len(values) >= 6, t["ticks"]
            page.locator("#timeline-row").screenshot(
                path=os.path.join(shots, f"timeline-seconds-{width}.png")
            )
        for width in (400, 150):
            check_timeline(redraw_at(p, width))
        redraw_at(p, None)

        # Dates (48 hourly steps from 06:00): round clock times, a midnight written as its date.
        open_dataset(p, HOURLY)
        t = redraw_at(p, None)
        check_timeline(t)
        assert t["axis"] == "date" and len(t["ticks"]) >= 3, t["ticks"]
        assert "2024-01-02" in t["ticks"] and "2024-01-03" in t["ticks"], t["ticks"]
        assert all(re.fullmatch(r"2024-01-0[23]|\d\d:00", x) for x in t["ticks"]), t["ticks"]
        hours = [0 if "-" in x else int(x[:2]) for x in t["ticks"]]
        every = (hours[1] - hours[0]) % 24 or 24
        assert every in (1, 2, 3, 6, 12, 24), t["ticks"]
        assert all((b - a) % 24 == every % 24 for a, b in itertools.pairwise(hours)), t["ticks"]
        page.locator("#timeline-row").screenshot(path=os.path.join(shots, "timeline-hourly.png"))
        for width in (600, 250, 100):
            check_timeline(redraw_at(p, width))
    finally:
        p.close()


# ------------------------------------------------- 1b: the timeline's time-colour cells per view
# Each row of cells as drawn: its views, steps and whether it is the selected view's, with the
# canvas' pixel (r, g, b, a) at the middle of its first cell, each view's legend (step -> rgb)
# and the canvas' tooltip.
ROWS = """() => {
  const c = document.getElementById('timeline');
  const L = window.viewer.timelineLayout;
  const k = c.width / L.width;
  const cell = L.width / window.viewer.S.info.shape.t;
  const ctx = c.getContext('2d');
  return {
    rows: L.rows.map((r) => ({...r, pixel: [...ctx.getImageData(
      Math.floor((r.steps[0] + 0.5) * cell * k), Math.floor((r.y + r.h / 2) * k), 1, 1).data]})),
    legends: window.viewer.S.legends.map((l) => Object.fromEntries(
      l.map((x) => [x.step, x.rgb.map((v) => Math.round(v * 255))]))),
    title: c.title,
  };
}"""


def own_window(p: Page, view: int, text: str) -> dict:
    field = f'.view[data-i="{view}"] input.own-window'
    return act(p, lambda: (p.page.fill(field, text), p.page.press(field, "Enter")))


def test_the_timeline_shows_each_views_cells(browser, server, tmp_path):  # noqa: F811
    shots = shots_dir(tmp_path)
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        act(p, lambda: page.select_option("#nviews", "2"))
        # Both views linked: one row, the timeline's window 5:15, as with one view.
        t = p.eval(ROWS)
        assert [(r["views"], r["steps"]) for r in t["rows"]] == [([0, 1], list(range(5, 15)))]
        assert "top to bottom" not in t["title"]

        # The second view's own window: a row of its own under the first's, at its steps, in
        # its legend's colours; the selected (first) view's row bright, the other's faded.
        own_window(p, 1, "0:4")
        t = p.eval(ROWS)
        rows = t["rows"]
        assert [(r["views"], r["steps"]) for r in rows] == [
            ([0], list(range(5, 15))),
            ([1], [0, 1, 2, 3]),
        ]
        assert [r["selected"] for r in rows] == [True, False]
        assert rows[0]["y"] + rows[0]["h"] <= rows[1]["y"] and min(r["h"] for r in rows) >= 3
        bright, faded = rows[0]["pixel"], rows[1]["pixel"]
        assert bright[3] == 255 and np.allclose(bright[:3], t["legends"][0]["5"], atol=3)
        assert 60 < faded[3] < 160, faded  # (nothing under it: the window starts at 5)
        assert "view 1: steps 5:15" in t["title"] and "view 2: own window 0:4" in t["title"]
        check_timeline(p.eval(TIMELINE))  # the axis' labels: nothing draws over them
        page.locator("#timeline-row").screenshot(path=os.path.join(shots, "timeline-rows.png"))

        # The second view selected (a click on its picture): its row is the bright one.
        page.locator('.view[data-i="1"] img').click()
        page.wait_for_function("() => window.viewer.timelineLayout.rows[1].selected")
        rows = p.eval(ROWS)["rows"]
        assert [r["selected"] for r in rows] == [False, True] and rows[1]["pixel"][3] == 255

        # The same window again but the first view's own time colours: still two rows, at the
        # same steps, in each view's colours.
        own_window(p, 1, "")
        act(p, lambda: page.locator('.view[data-i="0"] .link[data-link="time_tf"]').click())
        colour = p.eval(
            """() => [...document.getElementById('time-color').options].map((o) => o.value)
                     .find((v) => v !== window.viewer.S.state.views[0].time_tf.color)"""
        )
        page.eval_on_selector("#time-color", "(el) => el.closest('details').open = true")
        act(p, lambda: page.select_option("#time-color", colour))
        t = p.eval(ROWS)
        assert [(r["views"], r["steps"]) for r in t["rows"]] == [
            ([0], list(range(5, 15))),
            ([1], list(range(5, 15))),
        ]
        assert t["legends"][0] != t["legends"][1] and "own time TF" in t["title"]
        check_timeline(p.eval(TIMELINE))
        page.locator("#timeline-row").screenshot(
            path=os.path.join(shots, "timeline-rows-own-time-tf.png")
        )

        # Linked again: one row.
        act(p, lambda: page.locator('.view[data-i="0"] .link[data-link="time_tf"]').click())
        assert [r["views"] for r in p.eval(ROWS)["rows"]] == [[0, 1]]
    finally:
        p.close()


# ------------------------------------------------------------------ 2: a new view's mode
VIEWS = """() => ({
  views: window.viewer.S.state.views.map((v) => [v.mode, v.order || 'forward']),
  labels: [...document.querySelectorAll('.view .view-label')].map((l) => l.title),
  data_tf: JSON.stringify(window.viewer.S.state.data_tf),
  time_tf: JSON.stringify(window.viewer.S.state.time_tf),
})"""


def test_a_new_view_copies_the_selected_views_mode(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        act(p, lambda: page.select_option('.view[data-i="0"] select.mode', "max"))
        page.wait_for_function("() => window.viewer.S.fits.some((f) => f.mode === 'max')")
        p.settle({"seq": 0})  # the default curve fitted to max
        act(p, lambda: page.locator(".view .order").first.click())  # backward
        before = p.eval(VIEWS)
        act(p, lambda: page.select_option("#nviews", "2"))
        got = p.eval(VIEWS)
        assert got["views"] == [["max", "backward"], ["max", "backward"]]
        assert [label.split(", steps")[0] for label in got["labels"]] == ["max, backward"] * 2
        # One pair of transfer functions for every view: the new one draws under the same.
        assert (got["data_tf"], got["time_tf"]) == (before["data_tf"], before["time_tf"])

        # The second view made min and selected (a click on its picture): a third copies it.
        act(p, lambda: page.select_option('.view[data-i="1"] select.mode', "min"))
        page.locator('.view[data-i="1"] img').click()
        assert p.eval("() => window.viewer.S.selectedView") == 1
        act(p, lambda: page.select_option("#nviews", "3"))
        assert p.eval(VIEWS)["views"] == [["max", "backward"], *[["min", "backward"]] * 2]
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "new-view-copies-mode.png"))

        # The page's address keeps the views: a reload shows them again.
        page.wait_for_function("() => location.hash.startsWith('#state=')")
        page.reload()
        page.wait_for_function("() => window.viewer && window.viewer.full >= 1", timeout=60_000)
        p.settle()
        assert p.eval(VIEWS)["views"] == [["max", "backward"], *[["min", "backward"]] * 2]
    finally:
        p.close()


# ------------------------------------------------------------------- 3: the data set menu
MENU = """() => {
  const s = document.getElementById('dataset');
  const cs = getComputedStyle(s);
  const ctx = document.createElement('canvas').getContext('2d');
  ctx.font = `${cs.fontWeight} ${cs.fontSize} ${cs.fontFamily}`;
  const text = s.options[s.selectedIndex].text;
  const rows = [...document.querySelectorAll('#bar .bar-row')].map(
    (r) => Math.round(r.getBoundingClientRect().height));
  const outside = [...document.querySelectorAll('#bar button, #bar select, #bar label')]
    .filter((el) => { const r = el.getBoundingClientRect();
      return r.left < 0 || r.right > innerWidth + 0.5; }).length;
  return {
    text, title: s.title, need: ctx.measureText(text).width,
    // the room for the text: the box less its padding, border and the menu's arrow (20 px)
    room: s.clientWidth - parseFloat(cs.paddingLeft) - parseFloat(cs.paddingRight) - 20,
    rows, outside,
  };
}"""


@pytest.mark.parametrize("width", [1400, 1000])
def test_the_data_set_menu_shows_the_name_and_shape_whole(browser, server, tmp_path, width):  # noqa: F811
    p = Page(browser, server, width, 900)
    try:
        m = p.eval(MENU)
        assert m["text"] == f"{LONG} (96×32×24, 20 steps)"
        assert m["need"] <= m["room"], m  # not cut
        assert all(s in m["title"] for s in (LONG, "96×32×24", "20 steps", "float32")), m
        assert len(m["rows"]) == 2 and all(h <= 34 for h in m["rows"]) and m["outside"] == 0, m
        # The words the narrow header leaves out are their menus' tooltips.
        assert p.eval("() => document.getElementById('projection').title") == "Projection"
        p.page.locator("#bar").screenshot(
            path=os.path.join(shots_dir(tmp_path), f"menu-{width}.png")
        )
        open_dataset(p, CUBE)
        assert p.eval(MENU)["text"] == "vortex (32³, 12 steps)"
    finally:
        p.close()


# ----------------------------------------------------------------------- 4: the fit's note
NOTE = """() => { const el = document.getElementById('tf-range');
  return {text: el.textContent, stale: el.classList.contains('stale')}; }"""


def test_the_fit_note_says_what_the_curve_is_fitted_to_now(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        note = p.eval(NOTE)
        assert note["text"].endswith("(fitted to alpha, window 5:15)") and not note["stale"]
        # The curve edited by hand (a point's opacity), then another mode: not fitted again,
        # and the note says the view now shows another mode.
        page.fill("#point-alpha", "0.5")
        act(p, lambda: page.press("#point-alpha", "Enter"))
        act(p, lambda: page.select_option('.view[data-i="0"] select.mode', "max"))
        page.wait_for_timeout(500)  # no fit comes (a curve edited by hand is fitted by F alone)
        note = p.eval(NOTE)
        assert "fitted to alpha, window 5:15" in note["text"], note
        assert "now shows max, window 5:15" in note["text"] and note["stale"], note
        page.screenshot(path=os.path.join(shots_dir(tmp_path), "fit-note-after-mode-switch.png"))
        # Fitted again (the button, F): the note says so, and nothing more.
        fits = p.eval("() => window.viewer.S.fits.length")
        page.click("#tf-fit")
        page.wait_for_function(f"() => window.viewer.S.fits.length > {fits}")
        page.wait_for_function(
            "() => !document.getElementById('tf-range').classList.contains('stale')"
        )
        assert p.eval(NOTE)["text"].endswith("(fitted to max, window 5:15)")
        # The window slid: the note names the window shown.
        p.eval("() => document.activeElement.blur()")  # keys act where no field has the focus
        act(p, lambda: page.keyboard.press("ArrowRight"))
        note = p.eval(NOTE)
        assert "fitted to max, window 5:15" in note["text"], note
        assert "now shows max, window 6:16" in note["text"] and note["stale"], note
        # Back where it was fitted: the plain note again.
        act(p, lambda: page.keyboard.press("ArrowLeft"))
        assert p.eval(NOTE) == {"text": note["text"].split(";")[0] + ")", "stale": False}
    finally:
        p.close()


# -------------------------------------------------------------- 5: a nearly empty view's note
NOTES = """() => [...document.querySelectorAll('#views .view')].map((v) => {
  const box = (el) => { const r = el.getBoundingClientRect();
    return {x: r.left, y: r.top, w: r.width, h: r.height}; };
  const n = v.querySelector('.view-note');
  const cs = getComputedStyle(n);
  return {pic: box(v.querySelector('.view-pic img')), note: box(n), visible: n.checkVisibility(),
          text: n.textContent, title: n.title, font: parseFloat(cs.fontSize)};
})"""


def check_notes(notes: list[dict]) -> None:
    for n in notes:
        assert n["visible"] and "almost nothing is visible" in n["text"], n
        pic, box = n["pic"], n["note"]
        # Inside the picture, in a strip at its foot: clear of the middle half each way.
        middle = {"x": pic["x"] + pic["w"] / 4, "y": pic["y"] + pic["h"] / 4}
        middle |= {"w": pic["w"] / 2, "h": pic["h"] / 2}
        assert not intersects(box, middle), n
        assert box["y"] + box["h"] <= pic["y"] + pic["h"] + 0.5 and box["h"] <= 0.25 * pic["h"]
        assert box["x"] >= pic["x"] - 0.5 and box["x"] + box["w"] <= pic["x"] + pic["w"] + 0.5
        assert n["font"] >= 11 and n["title"] == n["text"]  # readable; whole in its tooltip


def test_an_empty_views_note_keeps_clear_of_the_picture(browser, server, tmp_path):  # noqa: F811
    shots = shots_dir(tmp_path)
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        open_dataset(p, CUBE)
        act(p, lambda: page.select_option('.view[data-i="0"] select.mode', "min"))
        page.wait_for_function("() => window.viewer.S.fits.some((f) => f.mode === 'min')")
        p.settle({"seq": 0})  # the default curve fitted to min
        page.wait_for_function("() => !document.querySelector('.view-note').hidden")
        check_notes(p.eval(NOTES))
        page.screenshot(path=os.path.join(shots, "empty-note-1-view.png"))
        act(p, lambda: page.select_option("#nviews", "4"))  # copies of the min view
        page.wait_for_timeout(300)  # the resize observer's debounce
        p.settle({"seq": 0})
        page.wait_for_function(
            "() => [...document.querySelectorAll('.view-note')].every((n) => !n.hidden)"
        )
        check_notes(p.eval(NOTES))
        page.screenshot(path=os.path.join(shots, "empty-note-4-views.png"))
        act(p, lambda: page.select_option('.view[data-i="0"] select.mode', "alpha"))
        assert not page.locator('.view[data-i="0"] .view-note').is_visible()
    finally:
        p.close()
