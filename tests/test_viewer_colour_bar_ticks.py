"""Target 1 of issue 49: a PNG saved from the viewer (Save PNG) and one from `chronocl render
--state` of the same saved session both carry the data colour bar with ticks in data units.

A series whose values run from 100 to 1100 is shown in max mode under a viridis data TF over
that range. In each PNG the test finds the bar (the longest row run of viridis' colours in
order, `test_colour_bar.longest_map_run`'s matching, with where it lies) and the tick marks
under it (the columns inked in the three rows between the bar and its labels), and checks the
marks stand where the 1-2-5 multiples of a nice step in [100, 1100] fall when the range is
mapped onto the bar's first and last columns, within a pixel; both PNGs give the same ticks.

The PNGs go to $CHRONOCL_SCREENSHOTS (else the test's temporary folder).
"""

from __future__ import annotations

import io
import json
import os

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from chronocl.core.tf import DataTF
from chronocl.core.ticks import MANTISSAS, multiples
from chronocl.data import synthetic
from chronocl.data.timeseries import TimeSeries

from .test_colour_bar import map_colours
from .viewer_helpers import Client, full_size_frames, start_server  # noqa: F401

pytestmark = pytest.mark.usefixtures("full_size_frames")

LO, HI = 100.0, 1100.0
SIZE = (320, 200)  # the panel, w x h


def bar_of(image: np.ndarray, name: str = "viridis") -> tuple[int, int, int]:
    """(last row, first column, last column) of the colour bar of map `name` in `image`
    (H, W, 3): the rows holding the longest run of the map's colours in increasing order, that
    covers nearly all of the map."""
    lut = map_colours(name)
    rgb = image.astype(np.float64)
    best: dict[int, tuple[int, int]] = {}  # row -> (x0, x1) of its run covering the map
    for y in range(rgb.shape[0]):
        row = rgb[y]
        dist = np.linalg.norm(row[:, None, :] - lut[None, :, :], axis=-1)
        index, near = dist.argmin(axis=1), dist.min(axis=1) < 10.0
        start = 0
        for x in range(1, len(row) + 1):
            if x < len(row) and near[x] and near[x - 1] and index[x] >= index[x - 1] - 3:
                continue
            cover = (index[x - 1] - index[start]) / (len(lut) - 1)
            if near[start] and cover > 0.9 and x - start > 50:
                if x - start > best.get(y, (0, -1))[1] - best.get(y, (0, -1))[0]:
                    best[y] = (start, x - 1)
            start = x
    assert best, "no colour bar of the map found"
    longest = max(x1 - x0 for x0, x1 in best.values())
    rows = sorted(y for y, (x0, x1) in best.items() if x1 - x0 >= longest - 2)
    assert rows == list(range(rows[0], rows[-1] + 1)) and len(rows) >= 6, rows  # one band
    x0, x1 = best[rows[0]]
    return rows[-1], x0, x1


def tick_columns(image: np.ndarray, bottom: int, x0: int, x1: int) -> list[float]:
    """The x of each tick mark under the bar: the columns within the bar's span inked in the
    three rows below its last row (its labels start under them), runs merged to their middle."""
    band = image[bottom + 1 : bottom + 4, x0 - 2 : x1 + 3].astype(int)
    bg = np.median(band.reshape(-1, 3), axis=0)
    inked = (np.abs(band - bg).max(axis=-1) > 60).sum(axis=0) >= 2
    xs = np.flatnonzero(inked)
    runs = np.split(xs, np.flatnonzero(np.diff(xs) > 1) + 1) if len(xs) else []
    return [float(r.mean()) + x0 - 2 for r in runs]


def ticks_in_data_units(image: np.ndarray) -> list[float]:
    """The colour bar's ticks of `image`, checked to stand where the multiples of a 1-2-5
    step in [LO, HI] map onto the bar (LO at its first column, HI at its last); their values."""
    bottom, x0, x1 = bar_of(image)
    found = tick_columns(image, bottom, x0, x1)
    assert len(found) >= 3, found
    for e in range(-1, 5):
        for m in MANTISSAS:
            values = multiples(LO, HI, m * 10.0**e)
            want = [x0 + (v - LO) / (HI - LO) * (x1 - x0) for v in values]
            if len(want) == len(found) and np.allclose(want, found, atol=1.0):
                return values
    raise AssertionError(f"ticks at {found} are no nice step's over [{x0}, {x1}]")


def test_saved_png_and_render_state_have_the_bar_with_ticks_in_data_units(tmp_path):
    from PIL import Image
    from typer.testing import CliRunner

    from chronocl.cli.app import app

    from .test_viewer_server import get

    shots = os.environ.get("CHRONOCL_SCREENSHOTS", str(tmp_path))
    os.makedirs(shots, exist_ok=True)
    raw = np.stack(list(synthetic.steps("vortex", 12, (32, 32, 32)))).astype(np.float64)
    data = (LO + (HI - LO) * (raw - raw.min()) / (raw.max() - raw.min())).astype(np.float32)
    store = tmp_path / "vortex.zarr"
    TimeSeries.from_array(data, source="vortex").save(store)
    viridis = DataTF().with_colormap("viridis")

    server = start_server([store])
    try:
        c = Client(server)
        c.open(0, size=SIZE)
        rid = c.send(
            {
                "type": "update",
                "views": [{"mode": "max"}],
                "window": {"t0": 2, "t1": 10, "stride": 1},
                "data_tf": {"points": [list(p) for p in viridis.points], "value_range": [LO, HI]},
            }
        )
        _, header, _ = c.frame_for(rid)
        assert header["quality"] == "full" and not header["reduced"]
        pngs = {}
        for what in ("image", "session"):
            rid = c.send({"type": "save", "what": what})
            _, dl = c.wait("download", rid)
            status, body, _ = get(server.base + dl["url"], {"X-Chronocl-Token": server.token})
            assert status == 200
            pngs[what] = body
        c.close()
    finally:
        server.stop()

    session = tmp_path / "vortex-session.json"
    session.write_bytes(pngs["session"])
    assert json.loads(pngs["session"])["data_tf"]["value_range"] == [LO, HI]
    out = tmp_path / "rendered.png"
    result = CliRunner().invoke(app, ["render", "--state", str(session), "-o", str(out)])
    assert result.exit_code == 0, result.output

    saved = np.asarray(Image.open(io.BytesIO(pngs["image"])).convert("RGB"))
    rendered = np.asarray(Image.open(out).convert("RGB"))
    Image.fromarray(saved).save(os.path.join(shots, "colour-bar-ticks-viewer.png"))
    Image.fromarray(rendered).save(os.path.join(shots, "colour-bar-ticks-render-state.png"))
    from_viewer = ticks_in_data_units(saved)
    from_cli = ticks_in_data_units(rendered)
    assert from_viewer == from_cli, (from_viewer, from_cli)
    assert len(from_viewer) >= 3 and from_viewer[0] >= LO and from_viewer[-1] <= HI
