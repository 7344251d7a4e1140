"""The notebook widget's latency beside the browser viewer's, in one run on one machine.

The built-in vortex is written as a chronocl store with its coarse levels (256^3 float32 x 20
steps by default). A JupyterLab server on loopback runs a notebook in headless Chromium
(Playwright), started and driven as tests/test_notebook_browser.py does it (tests/jupyter_lab.py,
which both import); a viewer server (`ViewerServer`, in this process) serves the same store to
a second Chromium page, its view panel sized as the widget's. Timed:

- the widget's first picture: from the cell `w = chronocl.show(store, window=(0, 10)); w`
  being run (the page's clock as JupyterLab is told to run it) to the first frame in the
  widget (`first_picture_ms`), and to its first sharp frame (`first_sharp_ms`: level 0, full
  quality, not refining). `import chronocl` runs in the cell before, timed in the kernel
  (`import_s`): a kernel imports it once, whatever it shows after. Then the same for a second
  widget of the store in the same kernel, the first closed (`again_first_picture_ms`,
  `again_first_sharp_ms`): what every `show` after a kernel's first waits;
- data-TF edits by hand, in the widget and on the viewer page alike: an opacity handle dragged
  with the mouse and let go, each to a value no edit before had, timed from the release's
  request to its sharp frame (`viewer.last.roundTripMs`, the page's own clock), the first
  COLD_EDITS apart from the rest as in bench/viewer_latency.py;
- a scrub, in the widget and on the viewer page alike, after the edits, the two pages taking
  turns slide by slide (so that both meet the same load; which goes first alternates): the
  window brushed by hand over the series' last steps (where the widget's and the page's windows
  differ before), then dragged by hand one step at a time along the timeline (pressed inside it,
  moved one step's width, let go; to the series' start and back), as many slides as `--slides`.
  Each slide is timed on the page's clock from its drag's first input (the pointer move that
  moved the window; its request, a preview, goes on the next animation frame) to the first frame
  answering the drag (`first_frame_ms`) and to the sharp frame answering the release
  (`sharp_ms`), and from the release to that sharp frame (`release_sharp_ms`). Frames are seen
  as they arrive (an observer of the page's frame count), not polled. Slide 1 is the cold one
  (the session's first slide), slide 10 the warm one the issue names; p50 / p95 / max are over
  slides COLD_SLIDES + 1 on.

One JSON line for the environment, then one with the summary: `first_picture_ms`,
`first_sharp_ms`, `import_s`, `show_s` (the `show` call in the kernel), `widget_view_ms` (the
cell run to the widget's view on the page: the front end loaded, the viewer's modules linked),
`widget_tf_sharp_ms` / `viewer_tf_sharp_ms` (p50, p95, max of the warm edits) and
`*_cold_tf_sharp_ms`, `ratio_tf_sharp_p50` (widget over viewer; issue 50: within 1.2), the
scrub's `widget_scrub` / `viewer_scrub` (each: the first and the tenth slide's `first_frame_ms`,
`sharp_ms` and `release_sharp_ms`, and p50 / p95 / max of the warm slides' `sharp_ms`,
`first_frame_ms`, `release_sharp_ms` and `transit_ms`: a frame's round trip less the worker's
time on it, the way to the worker and back; `sharp_server_ms`, the worker's time on the sharp
frame; `page_task_ms` and `page_updates`, the page's main-thread task time and layouts over a
slide, from Chromium's counters: where the widget's time goes beside the viewer's), their
ratios `ratio_scrub_first_sharp`, `ratio_scrub_tenth_sharp`, `ratio_scrub_sharp_p50` and
`ratio_scrub_first_frame_p50` (widget over viewer; issue 50: a scrub's frames within 1.2), the
panels' sizes, and `targets`. One line
per slide before it (`"case": "scrub"`, `"impl": "widget"` or `"viewer"`).

    python bench/notebook_latency.py                 # 256^3 x 20, a 10-step window
    python bench/notebook_latency.py --quick         # 128^3 x 12
    python bench/notebook_latency.py --keep /tmp/nb  # keep the store there, reuse it
    python bench/notebook_latency.py --slides 20     # a longer scrub (default 12)
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # for tests.jupyter_lab

from common import emit, env_record, percentiles

from chronocl.data import synthetic
from chronocl.data.writer import write_store
from tests.jupyter_lab import (
    cell_output,
    jupyter_lab,
    open_notebook,
    run_cell,
    wait_kernel_idle,
    write_notebook,
)

BENCH = "notebook_latency"
CHROMIUM = "/usr/bin/chromium"
BROWSER_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking"]
VIEWPORT = (1400, 1000)
HEIGHT = 600  # the widget's height (issue 50: a cell output of about 900 x 600)
COLD_EDITS = 2
COLD_SLIDES = 3  # BENCH.md: the first three actions after an open are the cold ones
TARGETS = {
    "first_picture_ms": 1000, "ratio_tf_sharp_p50": 1.2, "ratio_scrub_sharp_p50": 1.2,
    "ratio_scrub_first_frame_p50": 1.2,
}  # fmt: skip
WIDGET = "document.querySelector('.chronocl-widget').viewer"
# Where the viewer's elements are: the widget's shadow root, the viewer page's document.
WIDGET_ROOT = "document.querySelector('.chronocl-widget').shadowRoot"
PAGE_ROOT = "document"
# A widget's page holds its first frame.
FIRST_FRAME = (
    "() => { const h = document.querySelector('.chronocl-widget');"
    " return !!h && !!h.viewer && h.viewer.frames >= 1; }"
)
PAGE = "window.viewer"
# A slide's recorder, installed before its drag: the page's clock at the drag's first input
# (the first pointer move on the timeline that moved the window: the viewer merges it into its
# state at once and sends it on the next animation frame, on either page), at the release, at
# the first frame answering a request sent since and at the sharp frame answering the release
# (a request sent after it: level 0, full quality, not refining), each frame seen as it arrives
# (an observer of the frame count the viewer writes on its element), and those two frames'
# transit (the round trip less the worker's `server_ms`). The listeners run after the viewer's
# own. Left in `window.__slide`.
RECORD_SLIDE = """() => {
  const v = %s, root = %s;
  const timeline = root.querySelector('#timeline'), shell = root.querySelector('[data-frames]');
  const t0 = v.S.state.window.t0;
  const rec = { sent: v.sent, start: null, release: null, releasedAfter: null, first: null,
                sharp: null, frames: 0, window: null };
  const moved = () => {
    if (rec.start === null && v.S.state.window.t0 !== t0) rec.start = performance.now();
  };
  const released = () => { rec.release = performance.now(); rec.releasedAfter = v.sent; };
  timeline.addEventListener('pointermove', moved);
  timeline.addEventListener('pointerup', released);
  const seen = new MutationObserver(() => {
    const l = v.last, now = performance.now();
    if (l.id === null || l.id <= rec.sent) return;
    rec.frames += 1;
    const transit = (f) => (f.roundTripMs === null || !f.timings ? null
      : f.roundTripMs - f.timings.server_ms);
    if (rec.first === null) { rec.first = now; rec.firstTransit = transit(l); }
    if (rec.releasedAfter !== null && l.id > rec.releasedAfter && l.quality === 'full'
        && !l.refining && l.level === 0) {
      rec.sharp = now;
      rec.sharpTransit = transit(l);
      rec.sharpTimings = l.timings || null;
      rec.window = [v.S.state.window.t0, v.S.state.window.t1];
      seen.disconnect();
      timeline.removeEventListener('pointermove', moved);
      timeline.removeEventListener('pointerup', released);
    }
  });
  seen.observe(shell, { attributes: true, attributeFilter: ['data-frames'] });
  window.__slide = rec;
}"""
# A sharp frame after frame `seq`, answering the newest request.
SHARP = """([seq]) => {
  const v = %s, l = v && v.last;
  return !!l && l.seq > seq && l.quality === 'full' && !l.refining && l.level === 0
    && l.id !== null && l.id >= v.sent;
}"""


def store(root: Path, n: int, steps: int) -> Path:
    path = root / f"vortex-{n}-{steps}.zarr"
    if not path.exists():
        shape = (n, n, n)
        write_store(
            path, synthetic.steps("vortex", steps, shape), n_steps=steps, volume_shape=shape,
            dtype=np.float32, source="vortex",
        )  # fmt: skip
    return path


def notebook(path: Path, data: Path, window: int) -> int:
    """The bench's notebook written to `path`; its number of cells."""
    cells = [
        "import json, time\nt = time.perf_counter()\nimport chronocl\n"
        "print('IMPORT=' + json.dumps({'s': time.perf_counter() - t}))",
        f"t = time.perf_counter()\n"
        f"w = chronocl.show({str(data)!r}, window=(0, {window}), height={HEIGHT})\n"
        "show_s = time.perf_counter() - t\nw",
        "print('SHOW=' + json.dumps({'s': show_s}))\nw.close()",
        f"w = chronocl.show({str(data)!r}, window=(0, {window}), height={HEIGHT})\nw",
        "w.close()",
    ]
    write_notebook(path, cells)
    return len(cells)


def sharp(page, viewer: str, seq: int) -> dict:
    page.wait_for_function(SHARP % viewer, arg=[seq], timeout=120_000, polling="raf")
    return page.evaluate(f"() => {viewer}.last")


def tf_edits(page, viewer: str, n: int) -> list[float]:
    """`n` drags of one opacity handle, alternately up and down by a growing amount, each let
    go; the ms from the release's request to its sharp frame."""
    out = []
    handles = page.evaluate(f"() => {viewer}.tfHandles()")
    i = handles[len(handles) // 2]
    for k in range(n):
        before = page.evaluate(f"() => {viewer}.last")
        at = page.evaluate(f"(i) => {viewer}.tfPointAt(i)", i)
        dy = (6 + 2 * k) * (1 if k % 2 else -1)
        page.mouse.move(at["x"], at["y"])
        page.mouse.down()
        page.mouse.move(at["x"], at["y"] + dy / 2, steps=2)
        page.mouse.move(at["x"], at["y"] + dy, steps=2)
        page.mouse.up()
        last = sharp(page, viewer, before["seq"])
        out.append(float(last["roundTripMs"]))
        time.sleep(0.5)  # a user looks at it
    return out


class Scrub:
    """One page's scrub: one-step slides of the window dragged by hand on its timeline, to the
    series' start and back, one slide at a time (`slide`), so that two pages' slides alternate
    and meet the same load; each slide's times (RECORD_SLIDE's) in ms from its drag's first
    input, in `slides`."""

    def __init__(self, page, viewer: str, root: str) -> None:
        self.page, self.viewer, self.root = page, viewer, root
        self.slides: list[dict] = []
        self.direction = 1
        self.cdp = None  # the page's DevTools session (`page_metrics`)

    def window(self) -> list[int]:
        return self.page.evaluate(
            f"() => [{self.viewer}.S.state.window.t0, {self.viewer}.S.state.window.t1]"
        )

    def drag(self, a: int, b: int, steps: int = 4) -> None:
        """The mouse pressed on step `a` of the timeline, moved to step `b`, let go."""
        page, viewer = self.page, self.viewer
        at = page.evaluate(f"(s) => {viewer}.timelineAt(s)", a)
        to = page.evaluate(f"(s) => {viewer}.timelineAt(s)", b)
        page.mouse.move(at["x"], at["y"])
        page.mouse.down()
        page.mouse.move((at["x"] + to["x"]) / 2, at["y"], steps=steps // 2)
        page.mouse.move(to["x"], to["y"], steps=steps // 2)
        page.mouse.up()

    def prepare(self) -> None:
        """Both pages from the same place: the window brushed over the last steps by hand."""
        page, viewer = self.page, self.viewer
        page.evaluate(
            f"() => {self.root}.querySelector('#timeline').scrollIntoView({{block: 'center'}})"
        )
        time.sleep(0.3)
        self.steps = page.evaluate(f"() => {viewer}.S.info.shape.t")
        t0, t1 = self.window()
        if t1 != self.steps:
            before = page.evaluate(f"() => {viewer}.last")
            self.drag(self.steps - 1, self.steps - (t1 - t0))  # outside the window: a new one
            sharp(page, viewer, before["seq"])
            got = self.window()
            if got != [self.steps - (t1 - t0), self.steps]:
                raise RuntimeError(f"the window brushed to the last steps is {got}")

    def page_metrics(self) -> dict:
        """Chromium's performance counters of the page (its main thread's task time, the
        layouts it ran), through the DevTools protocol."""
        if self.cdp is None:
            self.cdp = self.page.context.new_cdp_session(self.page)
            self.cdp.send("Performance.enable")
        return {m["name"]: m["value"] for m in self.cdp.send("Performance.getMetrics")["metrics"]}

    def slide(self) -> None:
        page = self.page
        t0, t1 = self.window()
        if not (0 <= t0 + self.direction and t1 + self.direction <= self.steps):
            self.direction = -self.direction
        mid = (t0 + t1) // 2  # pressed inside the window, away from its edges: a move
        page.evaluate(RECORD_SLIDE % (self.viewer, self.root))
        before = self.page_metrics()
        self.drag(mid, mid + self.direction)
        page.wait_for_function("() => window.__slide.sharp !== null", timeout=120_000)
        after = self.page_metrics()
        rec = page.evaluate("() => window.__slide")
        if rec["window"] != [t0 + self.direction, t1 + self.direction]:
            raise RuntimeError(f"slide from {[t0, t1]} by {self.direction} showed {rec['window']}")
        self.slides.append(
            {
                "window": rec["window"],
                "first_frame_ms": round(rec["first"] - rec["start"], 1),
                "sharp_ms": round(rec["sharp"] - rec["start"], 1),
                "release_sharp_ms": round(rec["sharp"] - rec["release"], 1),
                "frames": rec["frames"],
                "first_transit_ms": rnd(rec.get("firstTransit")),
                "sharp_transit_ms": rnd(rec.get("sharpTransit")),
                # the worker's stages for the sharp frame (integrate, upload, render...)
                "sharp_timings": rec.get("sharpTimings"),
                # the page's main thread over the slide (Chromium's own counters): its tasks'
                # time (Playwright's polling for the sharp frame included, on either page) and
                # the layouts it ran
                "page_task_ms": rnd(1e3 * (after["TaskDuration"] - before["TaskDuration"])),
                "page_updates": int(after["LayoutCount"] - before["LayoutCount"]),
            }
        )


def scrub(scrubs: list[Scrub], n: int) -> None:
    """`n` slides on each page, the pages taking turns (which goes first alternating)."""
    for one in scrubs:
        one.prepare()
    time.sleep(1.0)
    for k in range(n):
        for one in scrubs if k % 2 == 0 else scrubs[::-1]:
            one.slide()
            time.sleep(0.3)  # a user looks at it before the next step


def rnd(ms: float | None) -> float | None:
    return None if ms is None else round(ms, 1)


def scrub_summary(slides: list[dict]) -> dict:
    """The first (cold) and tenth slide, and the warm slides' percentiles."""
    warm = slides[COLD_SLIDES:]
    keys = ("first_frame_ms", "sharp_ms", "release_sharp_ms")
    return {
        "slides": len(slides),
        "first": {k: slides[0][k] for k in keys},
        "tenth": {k: slides[9][k] for k in keys} if len(slides) >= 10 else None,
        "sharp_ms": percentiles([s["sharp_ms"] for s in warm]),
        "first_frame_ms": percentiles([s["first_frame_ms"] for s in warm]),
        "release_sharp_ms": percentiles([s["release_sharp_ms"] for s in warm]),
        # a frame's round trip less the worker's time on it (`server_ms`): the way to the
        # worker and back, queues included (the comm's, or the viewer's socket)
        "transit_ms": percentiles(
            [
                s[k]
                for s in warm
                for k in ("first_transit_ms", "sharp_transit_ms")
                if s[k] is not None
            ]
        ),
        # the worker's time on the sharp frame, and the page's main-thread time per slide
        "sharp_server_ms": percentiles(
            [s["sharp_timings"]["server_ms"] for s in warm if s["sharp_timings"]]
        ),
        "page_task_ms": percentiles([s["page_task_ms"] for s in warm]),
        "page_updates": percentiles([s["page_updates"] for s in warm]),
    }


def ratio(a: float | None, b: float | None) -> float | None:
    return None if a is None or b is None else round(float(a) / float(b), 2)


def panel(page, viewer: str) -> list[int]:
    return page.evaluate(f"() => {viewer}.S.state.size")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="128^3 x 12 steps")
    parser.add_argument("--size", type=int, default=None)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--window", type=int, default=10)
    parser.add_argument("--edits", type=int, default=6)
    parser.add_argument("--slides", type=int, default=12, help="one-step slides in the scrub")
    parser.add_argument("--keep", type=Path, default=None, help="keep the store here")
    args = parser.parse_args()
    n = args.size or (128 if args.quick else 256)
    steps = args.steps or (12 if args.quick else 20)
    from playwright.sync_api import TimeoutError as PlaywrightTimeout
    from playwright.sync_api import sync_playwright

    from chronocl.viewer.server import ViewerServer

    emit(env_record(BENCH, {"size": n, "steps": steps, "window": args.window}))
    with ExitStack() as stack:
        root = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        data = store(args.keep or root, n, steps)
        cells = notebook(root / "bench.ipynb", data, args.window)
        home = Path(stack.enter_context(tempfile.TemporaryDirectory()))
        server = stack.enter_context(jupyter_lab(root, home))
        p = stack.enter_context(sync_playwright())
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=BROWSER_ARGS)
        stack.callback(browser.close)

        # The notebook: import, then the widget's first picture, then TF edits by hand.
        lab = browser.new_context(viewport=dict(zip(("width", "height"), VIEWPORT, strict=True)))
        page = lab.new_page()
        open_notebook(page, server, "bench.ipynb", cells, timeout_s=120)
        run_cell(page, 0, wait=False)
        imported = cell_output(page, 0, "IMPORT", timeout_s=120)
        wait_kernel_idle(page)
        started = run_cell(page, 1, wait=False)
        page.wait_for_function(
            "() => !!document.querySelector('.chronocl-widget')", timeout=120_000, polling="raf"
        )
        view_ms = page.evaluate("(t) => performance.now() - t", started)
        page.wait_for_function(FIRST_FRAME, timeout=120_000, polling="raf")
        first_ms = page.evaluate("(t) => performance.now() - t", started)
        first = page.evaluate(f"() => {WIDGET}.last")
        last = sharp(page, WIDGET, -1)
        sharp_ms = page.evaluate("(t) => performance.now() - t", started)
        size = panel(page, WIDGET)
        time.sleep(1.0)
        widget_ms = tf_edits(page, WIDGET, args.edits)
        print(
            f"widget: first {first_ms:.0f} ms, sharp {sharp_ms:.0f}, edits {widget_ms}",
            file=sys.stderr,
        )

        # The browser viewer on the same store, its panel the widget's size.
        server = ViewerServer([data])
        server.start()
        stack.callback(server.stop)
        viewer = browser.new_context(viewport={"width": VIEWPORT[0], "height": VIEWPORT[1]})
        vpage = viewer.new_page()
        vpage.goto(server.url)
        sharp(vpage, PAGE, -1)
        width, height = VIEWPORT
        for _ in range(3):  # the page's panel to the widget's size, as near as its layout goes
            got = panel(vpage, PAGE)
            if abs(got[0] - size[0]) <= 4 and abs(got[1] - size[1]) <= 4:
                break
            width, height = width + size[0] - got[0], height + size[1] - got[1]
            vpage.set_viewport_size({"width": width, "height": height})
            with contextlib.suppress(PlaywrightTimeout):
                vpage.wait_for_function(
                    f"([w, h]) => {{ const s = {PAGE}.S.state.size;"
                    " return s[0] !== w || s[1] !== h; }",
                    arg=got,
                    timeout=5_000,
                )
        time.sleep(1.0)
        sharp(vpage, PAGE, vpage.evaluate(f"() => {PAGE}.last.seq") - 1)
        time.sleep(1.0)
        viewer_ms = tf_edits(vpage, PAGE, args.edits)
        vsize = panel(vpage, PAGE)

        # The scrub: the widget's and the page's slides taking turns.
        scrubs = [Scrub(page, WIDGET, WIDGET_ROOT), Scrub(vpage, PAGE, PAGE_ROOT)]
        scrub(scrubs, args.slides)
        widget_slides, viewer_slides = scrubs[0].slides, scrubs[1].slides

        run_cell(page, 2, wait=False)
        shown = cell_output(page, 2, "SHOW", timeout_s=120)
        page.wait_for_function("() => !document.querySelector('.chronocl-widget')")
        # A second widget in the same kernel: the imports, GL context and kernels warm.
        started = run_cell(page, 3, wait=False)
        page.wait_for_function(FIRST_FRAME, timeout=120_000, polling="raf")
        again_ms = page.evaluate("(t) => performance.now() - t", started)
        sharp(page, WIDGET, -1)
        again_sharp_ms = page.evaluate("(t) => performance.now() - t", started)
        run_cell(page, 4, wait=False)

    for impl, slides in (("widget", widget_slides), ("viewer", viewer_slides)):
        for k, slide in enumerate(slides, 1):
            emit({"bench": BENCH, "case": "scrub", "impl": impl, "slide": k, **slide})
    ws, vs = scrub_summary(widget_slides), scrub_summary(viewer_slides)

    warm_w, warm_v = widget_ms[COLD_EDITS:], viewer_ms[COLD_EDITS:]
    summary = {
        "bench": BENCH,
        "summary": {
            "size": n, "steps": steps, "window": args.window,
            "import_s": round(imported["s"], 2),
            "show_s": round(shown["s"], 3), "widget_view_ms": round(view_ms),
            "first_picture_ms": round(first_ms), "first_picture_level": first.get("level"),
            "first_picture_quality": first.get("quality"),
            "first_sharp_ms": round(sharp_ms), "first_sharp_seq": last["seq"],
            "again_first_picture_ms": round(again_ms),
            "again_first_sharp_ms": round(again_sharp_ms),
            "widget_panel": size, "viewer_panel": vsize,
            "widget_tf_sharp_ms": percentiles(warm_w), "viewer_tf_sharp_ms": percentiles(warm_v),
            "widget_cold_tf_sharp_ms": [round(v, 1) for v in widget_ms[:COLD_EDITS]],
            "viewer_cold_tf_sharp_ms": [round(v, 1) for v in viewer_ms[:COLD_EDITS]],
            "ratio_tf_sharp_p50": round(float(np.median(warm_w) / np.median(warm_v)), 2),
            "widget_scrub": ws, "viewer_scrub": vs,
            "ratio_scrub_first_sharp": ratio(ws["first"]["sharp_ms"], vs["first"]["sharp_ms"]),
            "ratio_scrub_tenth_sharp": (
                ratio(ws["tenth"]["sharp_ms"], vs["tenth"]["sharp_ms"]) if ws["tenth"] else None
            ),
            "ratio_scrub_sharp_p50": ratio(ws["sharp_ms"].get("p50"), vs["sharp_ms"].get("p50")),
            "ratio_scrub_first_frame_p50": ratio(
                ws["first_frame_ms"].get("p50"), vs["first_frame_ms"].get("p50")
            ),
            "targets": TARGETS,
        },
    }  # fmt: skip
    emit(summary)


if __name__ == "__main__":
    main()
