"""The viewer's Save PNG is annotated as `chronocl render` draws its pictures (issue 49): a title
band naming the data set and the window (steps, and times with their unit), each view captioned
with its mode and window over its own legend (the time legend, count's bar, the data colour bar),
the title and captions also in the PNG's text; the pictures are the frames the page shows.
Movies' frames are composed the same way. Over the socket, no browser.

The saved PNGs go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import io
import os
import urllib.request

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from chronocl.core.tf import DataTF
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries
from chronocl.render.panels import compose

from .test_colour_bar import longest_map_run
from .viewer_helpers import Client, full_size_frames, serving  # noqa: F401

pytestmark = pytest.mark.usefixtures("full_size_frames")

TIMES = [0.5 * k for k in range(12)]  # seconds
SIZE = (192, 160)  # a panel, w x h


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    path = tmp_path_factory.mktemp("viewer-save") / "vortex.zarr"
    data = np.stack(list(synthetic.steps("vortex", 12, (32, 32, 32))))
    TimeSeries.from_array(data, source="vortex", times=TIMES, time_unit="s").save(path)
    yield from serving([path], gl_current=True)


@pytest.fixture
def client(server):
    c = Client(server)
    yield c
    c.close()


def fetch(server, url: str) -> bytes:
    req = urllib.request.Request(server.base + url, headers={"X-Chronocl-Token": server.token})
    with urllib.request.urlopen(req, timeout=30) as r:
        return r.read()


def crop(image: np.ndarray, box) -> np.ndarray:
    x, y, w, h = box
    return image[y : y + h, x : x + w]


def inked(region: np.ndarray, bg=(0, 0, 0)) -> float:
    """The fraction of `region`'s pixels that are not the background."""
    return float(np.any(np.abs(region.astype(int) - bg) > 40, axis=-1).mean())


def shots(tmp_path) -> str:
    path = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    os.makedirs(path, exist_ok=True)
    return path


def test_saved_png_has_title_captions_legends_and_the_frames_pictures(server, client, tmp_path):
    from PIL import Image

    client.open(0, size=SIZE)
    viridis = DataTF().with_colormap("viridis")
    rid = client.send(
        {
            "type": "update",
            "views": [{"mode": "alpha"}, {"mode": "count"}],
            "window": {"t0": 2, "t1": 10, "stride": 1},
            "data_tf": {"points": [list(p) for p in viridis.points]},
        }
    )
    _, header, jpegs = client.frame_for(rid)
    assert header["quality"] == "full" and not header["reduced"]
    rid = client.send({"type": "save", "what": "image"})
    _, dl = client.wait("download", rid)
    png = fetch(server, dl["url"])
    with open(os.path.join(shots(tmp_path), "viewer-save-annotated.png"), "wb") as f:
        f.write(png)
    pil = Image.open(io.BytesIO(png))
    image = np.asarray(pil.convert("RGB"))

    # The title and captions, as the PNG's text says them: name, window in steps and seconds.
    assert pil.text["Title"] == "vortex: steps 2:10 (8 steps), 1 s .. 4.5 s"
    assert pil.text["Description"].splitlines() == [
        "alpha, forward, 1 s .. 4.5 s (8 steps)",
        "count, forward, 1 s .. 4.5 s (8 steps)",
    ]
    assert [v["label"] for v in header["views"]] == pil.text["Description"].splitlines()

    layout = dl["layout"]
    w, h = SIZE
    assert layout["title"] == [0, 0, image.shape[1], layout["title"][3]]
    assert image.shape[:2] == (
        layout["title"][3] + layout["captions"][0][3] + h + layout["legends"][0][3],
        2 * w,
    )
    # Text in the title band and in each caption; the legends hold bars and ticks.
    assert inked(crop(image, layout["title"])) > 0.02
    for caption, legend in zip(layout["captions"], layout["legends"], strict=True):
        assert inked(crop(image, caption)) > 0.02
        assert inked(crop(image, legend)) > 0.1
    # Each picture is where the layout says, and is the frame the page was sent (JPEG's loss).
    for box, jpeg in zip(layout["pictures"], jpegs, strict=True):
        assert box[2:] == [w, h]
        frame = np.asarray(Image.open(io.BytesIO(jpeg)).convert("RGB"), dtype=float)
        assert np.abs(crop(image, box) - frame).mean() < 3.0
    # The alpha view's legend has the data colour bar (viridis' yellow end); the count view's
    # its count bar, not a time legend: no pure blue (the oldest step's colour) in its band.
    alpha_band, count_band = (crop(image, b) for b in layout["legends"])
    assert (np.abs(alpha_band.astype(int) - (253, 231, 37)).max(axis=-1) < 40).any()
    assert (np.abs(alpha_band.astype(int) - (0, 0, 255)).max(axis=-1) < 40).any()  # its time
    assert not (np.abs(count_band.astype(int) - (0, 0, 255)).max(axis=-1) < 60).any()
    assert (np.abs(count_band.astype(int) - (253, 231, 37)).max(axis=-1) < 40).any()


def test_movie_frames_are_composed_as_the_saved_png(server, client):
    import imageio.v3 as iio
    from PIL import Image

    client.open(0, size=(160, 128))
    viridis = DataTF().with_colormap("viridis")  # a coloured data TF: the frames have its bar
    rid = client.send({"type": "update", "data_tf": {"points": [list(p) for p in viridis.points]}})
    client.frame_for(rid)
    rid = client.send({"type": "save", "what": "image"})
    _, dl = client.wait("download", rid)
    still = np.asarray(Image.open(io.BytesIO(fetch(server, dl["url"]))).convert("RGB"))
    rid = client.send({"type": "save", "what": "movie", "movie": "orbit", "format": "gif"})
    while True:
        got = client.recv(120)
        if got[0] == "download" and got[1]["id"] == rid:
            break
    frames = iio.imread(fetch(server, got[1]["url"]), index=None, extension=".gif")
    assert frames.shape[1:3] == still.shape[:2]  # the title band and legends included
    title = dl["layout"]["title"]
    # The first frame is the still (GIF's palette aside), its title band too.
    assert np.abs(crop(frames[0][..., :3], title).astype(int) - crop(still, title)).mean() < 4
    # The data colour bar is in the first frame, as in the still: viridis in order over most of
    # a row of its legend band (GIF's palette: nearer than 25 to the map's colours).
    (legend,) = dl["layout"]["legends"]
    for image in (still, frames[0][..., :3]):
        length, cover = longest_map_run(crop(image, legend), "viridis", 25.0)
        assert cover > 0.9 and length > 0.5 * legend[2], (length, cover, legend)


def test_compose_puts_the_title_over_the_panels_untouched():
    rng = np.random.default_rng(49)
    panels = [rng.integers(0, 256, (40, 60, 3), dtype=np.uint8) for _ in range(3)]
    image, layout = compose(panels, ["a", "b", "c"], None, 2, (1.0, 1.0, 1.0), title="jet: x")
    tx, ty, tw, th = layout.title
    assert (tx, ty, tw) == (0, 0, 120) and th > 0
    assert inked(crop(image, layout.title), (255, 255, 255)) > 0.01
    for panel, box in zip(panels, layout.pictures, strict=True):
        assert np.array_equal(crop(image, box), panel)
        assert box[1] >= th
    assert layout.legends == [None, None, None]
    plain, untitled = compose(panels, ["a", "b", "c"], None, 2, (1.0, 1.0, 1.0))
    assert untitled.title is None and plain.shape[0] == image.shape[0] - th
