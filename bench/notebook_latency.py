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
  COLD_EDITS apart from the rest as in bench/viewer_latency.py.

One JSON line for the environment, then one with the summary: `first_picture_ms`,
`first_sharp_ms`, `import_s`, `show_s` (the `show` call in the kernel), `widget_view_ms` (the
cell run to the widget's view on the page: the front end loaded, the viewer's modules linked),
`widget_tf_sharp_ms` / `viewer_tf_sharp_ms` (p50, p95, max of the warm edits) and
`*_cold_tf_sharp_ms`, `ratio_tf_sharp_p50` (widget over viewer; issue 50: within 1.2), the
panels' sizes, and `targets`.

    python bench/notebook_latency.py                 # 256^3 x 20, a 10-step window
    python bench/notebook_latency.py --quick         # 128^3 x 12
    python bench/notebook_latency.py --keep /tmp/nb  # keep the store there, reuse it
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
TARGETS = {"first_picture_ms": 1000, "ratio_tf_sharp_p50": 1.2}
WIDGET = "document.querySelector('.chronocl-widget').viewer"
# A widget's page holds its first frame.
FIRST_FRAME = (
    "() => { const h = document.querySelector('.chronocl-widget');"
    " return !!h && !!h.viewer && h.viewer.frames >= 1; }"
)
PAGE = "window.viewer"
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


def panel(page, viewer: str) -> list[int]:
    return page.evaluate(f"() => {viewer}.S.state.size")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="128^3 x 12 steps")
    parser.add_argument("--size", type=int, default=None)
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--window", type=int, default=10)
    parser.add_argument("--edits", type=int, default=6)
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
            "targets": TARGETS,
        },
    }  # fmt: skip
    emit(summary)


if __name__ == "__main__":
    main()
