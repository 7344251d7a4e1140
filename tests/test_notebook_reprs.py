"""The notebook's rich reprs (`chronocl.data.repr_html`), without the notebook extra: a
TimeSeries's and a Chronovolume's HTML summary says what it is and carries a small picture,
read without touching the series at full resolution (level 0's reads counted or made to fail);
`chronocl.render`'s Image shows as a PNG."""

from __future__ import annotations

import base64
import io
import re

import dask.array as da
import numpy as np
import pytest
from PIL import Image as PILImage

import chronocl
from chronocl.data import repr_html, synthetic
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.writer import write_store

STEPS, SHAPE = 4, (64, 64, 128)  # (Z, Y, X): level 1 is 64x32x32 (x, y, z)


def write(path, levels: bool, times=(0.0, 0.5, 1.0, 1.5)):
    steps = list(synthetic.steps("vortex", STEPS, SHAPE))
    write_store(
        path,
        steps,
        n_steps=STEPS,
        volume_shape=SHAPE,
        dtype=np.float32,
        spacing=(0.5, 0.5, 2.0),
        times=list(times),
        source="vortex",
        levels=levels,
        chunk_bytes=8 * 64 * 128 * 4,
    )  # fmt: skip  (chunks of 8 z rows: 8 a step)
    series = chronocl.open_series(str(path))
    return series


def picture(html: str) -> np.ndarray:
    found = re.search(r'src="data:image/png;base64,([^"]+)"', html)
    assert found, html
    return np.asarray(PILImage.open(io.BytesIO(base64.b64decode(found.group(1)))))


def failing(data: da.Array) -> da.Array:
    """`data` as a dask array that raises when any block of it is computed."""

    def boom(block):
        raise AssertionError("level 0 was read for a repr")

    return data.map_blocks(boom, dtype=data.dtype)


def counted(data: da.Array, reads: list) -> da.Array:
    def note(block, block_info=None):
        reads.append(block_info[0]["chunk-location"])
        return block

    return data.map_blocks(note, dtype=data.dtype)


def test_series_summary_says_what_it_is_and_where(tmp_path):
    series = write(tmp_path / "v.zarr", levels=True)
    series.meta["time_unit"] = "ms"
    html = series._repr_html_()
    for text in (
        "128×64×64 (x, y, z) × 4 steps", "float32", "0 .. 1.5 ms", "0..1 (128×64×64, 64×32×32)",
        "(0.5, 0.5, 2) (dx, dy, dz)", str(tmp_path / "v.zarr"),
        "step 2, time 1.0 ms: max along z, level 1",
    ):  # fmt: skip
        assert text in html, text
    image = picture(html)
    assert image.shape == (32, 64)  # level 1's max along z
    assert image.max() > image.min()  # the vortex, not a blank


def test_series_with_levels_never_reads_level_0(tmp_path):
    series = write(tmp_path / "v.zarr", levels=True)
    series.data = failing(series.data)
    assert "level 1" in series._repr_html_()


def test_store_without_levels_reads_one_layer_of_one_step(tmp_path):
    series = write(tmp_path / "v.zarr", levels=False)
    reads: list = []
    series.data = counted(series.data, reads)
    n_chunks = int(np.prod(series.data.numblocks))
    html = series._repr_html_()
    assert "slice z=32, 1 in 2 voxels" in html
    assert 1 <= len(reads) < n_chunks / STEPS  # a layer of chunks, less than one step's
    assert {r[0] for r in reads} == {STEPS // 2}
    assert picture(html).shape == (
        32,
        64,
    )  # every 2nd voxel: at most TUNING.repr_picture_voxels across


def test_array_series_is_sampled_in_place():
    a = np.zeros((3, 200, 150, 300), dtype=np.float32)
    a[1, 100, 20:40, 10:50] = 1.0  # the middle step: a bright patch, y 20..40, x 10..50
    series = chronocl.TimeSeries.from_array(a, times=[0, 1, 2], time_unit="s")
    series.data = failing(series.data)  # the numpy array is read, strided; dask never
    html = series._repr_html_()
    assert "max along z, 1 in 4 voxels along each axis" in html and "in memory" in html
    assert "0 .. 2 s" in html
    image = picture(html)
    assert image.shape == (38, 75)  # (150, 300) every 4th voxel
    rows, cols = np.nonzero(image[::-1])  # y up on the picture
    assert rows.min() == 5 and rows.max() == 9 and cols.min() == 3 and cols.max() == 12


def test_chronovolume_summary_and_picture_composite_front_to_back():
    rgba = np.zeros((8, 6, 10, 4), dtype=np.float32)
    rgba[7, 0, 0] = (0.0, 0.0, 1.0, 1.0)  # blue on top (z largest), opaque
    rgba[0, 0, 0] = (1.0, 0.0, 0.0, 1.0)  # red under it: hidden
    rgba[0, 5, 9] = (0.5, 0.0, 0.0, 0.5)  # half-transparent red alone (premultiplied)
    meta = {
        "dataset": "vortex", "store": "/data/vortex.zarr",
        "selection": {"steps": [2, 3, 4, 5], "n_steps": 20},
        "time_labels": [0.2, 0.3, 0.4, 0.5], "time_unit": "s", "spec": {"mode": "max"},
        "spacing": {"x": 1.0, "y": 1.0, "z": 2.0}, "level": 0,
    }  # fmt: skip
    cv = Chronovolume(rgba, np.zeros((8, 6, 10), np.int32), meta)
    html = cv._repr_html_()
    for text in ("10×6×8 (x, y, z), RGBA float32", "max", "2:6 (4 of 20)", "0.2 .. 0.5 s",
                 "(1, 1, 2)", "/data/vortex.zarr", "t_index</th><td>yes"):  # fmt: skip
        assert text in html, text
    image = picture(html)
    assert image.shape == (6, 10, 3)
    assert tuple(image[5, 0]) == (0, 0, 255)  # y=0 is the bottom row
    assert tuple(image[0, 9]) == (128, 0, 0)
    assert image[2:4].max() == 0


def test_large_chronovolume_is_strided():
    cv = Chronovolume(np.zeros((300, 100, 200, 4), dtype=np.uint8), None, {"spec": {}})
    html = cv._repr_html_()
    assert "composited along z, 1 in 4 voxels" in html and "t_index</th><td>no" in html
    assert picture(html).shape == (25, 50, 3)


def test_repr_module_needs_no_notebook_extra():
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['anywidget'] = None; sys.modules['ipywidgets'] = None\n"
        "import numpy as np, chronocl\n"
        "s = chronocl.TimeSeries.from_array(np.ones((2, 8, 8, 8), np.float32))\n"
        "print('TimeSeries' in s._repr_html_())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"
    assert "anywidget" not in open(repr_html.__file__).read()


def test_render_result_displays_as_png():
    a = np.stack(list(synthetic.steps("vortex", 3, (24, 24, 24))))
    try:
        cv = chronocl.integrate(chronocl.TimeSeries.from_array(a), window="0:3", mode="max")
        image = chronocl.render(cv, size=(64, 48))
    except chronocl.ChronoclError as exc:  # no GL context in this process
        pytest.skip(str(exc))
    png = image._repr_png_()
    assert png.startswith(b"\x89PNG")
    assert PILImage.open(io.BytesIO(png)).size == (64, 48)


def test_a_series_whose_picture_cannot_be_read_still_shows_its_summary(tmp_path):
    """A damaged chunk (or a store out of reach) costs the picture, not the summary: a repr
    that raises makes the notebook print a traceback instead."""
    series = write(tmp_path / "v.zarr", levels=False)

    def boom(block):
        raise chronocl.core.errors.StoreCorruptError("chunk 3.0.0.0 is damaged")

    series.data = series.data.map_blocks(boom, dtype=series.data.dtype)
    html = series._repr_html_()
    assert "no picture: chunk 3.0.0.0 is damaged" in html and "<table>" in html
    assert "<img" not in html


def test_a_repr_that_cannot_be_made_falls_back_to_the_plain_one():
    cv = Chronovolume(np.zeros((2, 3, 4, 4), np.float32))
    cv.metadata["selection"] = {"steps": [5, 1], "n_steps": 3}  # not a selection chronocl wrote
    assert cv._repr_html_() is None
    assert "steps [5, 1] (not a selection of 3 steps)" in repr(cv)  # which never raises


def test_the_repr_and_the_summary_read_a_chronovolume_alike():
    """`Chronovolume.described` is what both say: its mode, steps and shape."""
    meta = {"spec": {"mode": "mean"}, "selection": {"steps": [1, 3, 5]}}  # no n_steps
    cv = Chronovolume(np.zeros((4, 5, 6, 4), np.float32), None, meta)
    assert cv.described() == ("mean", "1:6:2 (3 of 6)", "6×5×4 (x, y, z)")
    assert repr(cv) == "Chronovolume(6×5×4 (x, y, z), mode=mean, steps 1:6:2 (3 of 6), no t_index)"
    html = cv._repr_html_()
    for row in ("shape</th><td>6×5×4 (x, y, z), RGBA float32", "mode</th><td>mean",
                "steps</th><td>1:6:2 (3 of 6)"):  # fmt: skip
        assert row in html, row
    bare = Chronovolume(np.zeros((2, 3, 4, 4), np.float32))
    assert bare.described() == ("?", None, "4×3×2 (x, y, z)")
    assert repr(bare) == "Chronovolume(4×3×2 (x, y, z), mode=?, no t_index)"
    assert "steps</th>" not in bare._repr_html_()
