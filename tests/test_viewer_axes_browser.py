"""The box's axes in Chromium: with the header's "box" on, each view's picture carries tick
labels in the data's spacing units and the axis names x, y and z over its box's edges, inside
the picture and none on top of another, every named axis with its labels (in four small views
too, where an edge runs along the picture's border); they move when the camera turns, label
the part a clip plane keeps, and go with the box.

Screenshots go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("playwright.sync_api")

from .test_viewer_page_browser import Page, browser, drag, set_views, shots_dir  # noqa: F401
from .viewer_helpers import CHROMIUM, serving

pytestmark = pytest.mark.skipif(
    not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} missing ('apt-get install chromium')"
)

SPACING = (0.5, 1.0, 2.5)  # dx, dy, dz: z's ticks run to 27.5, x's to 15.5


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from chronocl.data import synthetic
    from chronocl.data.series import TimeSeries

    root = tmp_path_factory.mktemp("viewer-axes")
    data = np.stack(list(synthetic.steps("vortex", 8, (12, 24, 32))))
    path = root / "aniso.zarr"
    TimeSeries.from_array(data, spacing=SPACING, source="aniso").save(path)
    yield from serving([path])


# Each drawn text of the box's axes: its text, its box, its axis, and the picture's box.
LABELS = """() => [...document.querySelectorAll('#views .view')].map((v) => {
  const r = (el) => { const b = el.getBoundingClientRect();
    return {x: b.left, y: b.top, w: b.width, h: b.height}; };
  return {
    pic: r(v.querySelector('.view-pic')),
    texts: [...v.querySelectorAll('.box-axes text')].map((t) => ({
      text: t.textContent, name: t.classList.contains('axis-name'),
      axis: t.parentNode.dataset.axis, ...r(t) })),
  };
})"""


def overlap(a: dict, b: dict) -> float:
    ix = min(a["x"] + a["w"], b["x"] + b["w"]) - max(a["x"], b["x"])
    iy = min(a["y"] + a["h"], b["y"] + b["h"]) - max(a["y"], b["y"])
    return max(0.0, ix) * max(0.0, iy)


def check_readable(view: dict, names: int = 3, ticks: int = 6) -> None:
    """Tick labels that are numbers, the axes' names, each named axis with tick labels, all
    inside the picture, none on top of another."""
    texts, pic = view["texts"], view["pic"]
    numbers = [t for t in texts if not t["name"]]
    shown = [t["text"] for t in texts if t["name"]]
    assert len(shown) >= names and len(set(shown)) == len(shown) and set(shown) <= set("xyz")
    assert len(numbers) >= ticks and all(float(t["text"]) >= 0 for t in numbers)
    for axis in shown:  # (an axis along the picture's border too: its labels inside)
        assert any(t["axis"] == axis for t in numbers), (axis, texts)
    for t in texts:
        assert t["w"] > 2 and t["h"] > 6, t
        assert pic["x"] - 1 <= t["x"] and t["x"] + t["w"] <= pic["x"] + pic["w"] + 1, t
        assert pic["y"] - 1 <= t["y"] and t["y"] + t["h"] <= pic["y"] + pic["h"] + 1, t
    for i, a in enumerate(texts):
        for b in texts[i + 1 :]:
            assert overlap(a, b) < 1.0, (a, b)


def test_box_axes_are_labelled_and_follow_the_camera(browser, server, tmp_path):  # noqa: F811
    p = Page(browser, server, 1400, 900)
    try:
        page = p.page
        assert all(not v["texts"] for v in p.eval(LABELS))  # the box is off
        before = p.last()
        page.check("#outline")
        p.settle(before)
        shots = shots_dir(tmp_path)
        page.locator("#views").screenshot(path=os.path.join(shots, "box-axes.png"))
        view = p.eval(LABELS)[0]
        check_readable(view)
        z = [float(t["text"]) for t in view["texts"] if t["axis"] == "z" and not t["name"]]
        assert max(z) > 12  # in spacing units (2.5 per voxel), not voxels

        # Turning the camera moves the labels with the box.
        pic = view["pic"]
        cx, cy = pic["x"] + pic["w"] / 2, pic["y"] + pic["h"] / 2
        before = p.last()
        drag(page, {"x": cx, "y": cy}, {"x": cx + 140, "y": cy + 40})
        p.settle(before)
        turned = p.eval(LABELS)[0]
        check_readable(turned)
        moved = {(t["text"], t["axis"]): (t["x"], t["y"]) for t in turned["texts"]}
        was = {(t["text"], t["axis"]): (t["x"], t["y"]) for t in view["texts"]}
        same = [k for k in moved if k in was and np.hypot(*np.subtract(moved[k], was[k])) < 2]
        assert len(same) < len(moved) / 2, same
        page.locator("#views").screenshot(path=os.path.join(shots, "box-axes-turned.png"))

        # A clip plane keeping z >= the middle: z's labels from the plane's z on (voxel 5.5 of
        # 12, times 2.5), x and y still labelled; off again, z's below it again.
        page.eval_on_selector("#clip-on", "(el) => el.closest('details').open = true")
        page.select_option("#clip-axis", "0,0,1")  # answered too (the clip is off)
        before = p.settle({"seq": 0})
        page.check("#clip-on")
        p.settle(before)
        clipped = p.eval(LABELS)[0]
        check_readable(clipped, ticks=4)
        z = [float(t["text"]) for t in clipped["texts"] if t["axis"] == "z" and not t["name"]]
        assert z and min(z) >= 5.5 * SPACING[2], z
        page.locator("#views").screenshot(path=os.path.join(shots, "box-axes-clipped.png"))
        before = p.last()
        page.uncheck("#clip-on")
        p.settle(before)
        whole = p.eval(LABELS)[0]["texts"]
        z = [float(t["text"]) for t in whole if t["axis"] == "z" and not t["name"]]
        assert z and min(z) < 5.5 * SPACING[2], z

        # Four small views at a laptop's size: each still labelled, every axis (x's edge runs
        # along the picture's top), nothing on top of another.
        page.set_viewport_size({"width": 1024, "height": 700})
        set_views(p, 4)
        for view in p.eval(LABELS):
            check_readable(view, names=3, ticks=4)
        page.locator("#views").screenshot(path=os.path.join(shots, "box-axes-four.png"))

        before = p.last()
        page.uncheck("#outline")
        p.settle(before)
        assert all(not v["texts"] for v in p.eval(LABELS))
    finally:
        p.close()
