"""Slices through a chronovolume (`chronocl.render.slices`, `chronocl render --slice`): the
read-out at a voxel is the chronovolume's t_index and the series' raw value there at that
step; the picture's pixels are the slice's RGBA composited over the background (a numpy
oracle), each voxel drawn with the data's aspect ratio; the step map is the time colours of
the winning steps; bad slices are one line (exit 2 on the command line) before any work."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import chronocl
from chronocl.core.errors import ChronoclError
from chronocl.render.slices import (
    Slice,
    fit_box,
    parse_slice,
    render_slice,
    slice_colours,
    slice_picture,
    slice_steps,
    slice_value,
    slice_voxel,
    step_colours,
    step_map,
)

from .strategies import examples
from .test_cli import assert_one_line_error, cli

WINNER_MODES = ("max", "min", "first_hit")


def _series(data: np.ndarray, spacing=(1.0, 1.0, 1.0), times=None, unit=None):
    return chronocl.TimeSeries.from_array(
        data, spacing=spacing, times=times, source="slice-test", time_unit=unit
    )


def _plane_oracle(volume: np.ndarray, axis: str, index: int) -> np.ndarray:
    """The (rows, cols) plane, written out per axis: z -> (y up, x across), y -> (z up, x
    across), x -> (z up, y across); the top row is the highest index of the up axis."""
    if axis == "z":
        return volume[index, ::-1, :]
    if axis == "y":
        return volume[::-1, index, :]
    return volume[::-1, :, index]


@st.composite
def cases(draw):
    shape = draw(st.tuples(st.integers(1, 7), st.integers(1, 6), st.integers(1, 5)))  # z, y, x
    t = draw(st.integers(1, 6))
    # few distinct values: ties, and (first_hit's threshold) voxels no step reaches
    levels = draw(st.sampled_from([3, 50]))
    seed = draw(st.integers(0, 2**16))
    data = np.random.default_rng(seed).integers(0, levels, (t, *shape)).astype(np.float32)
    spacing = draw(st.tuples(*[st.sampled_from([0.5, 1.0, 2.5]) for _ in range(3)]))
    mode = draw(st.sampled_from(WINNER_MODES))
    stride = draw(st.integers(1, 2))
    timed = draw(st.booleans())
    axis = draw(st.sampled_from("xyz"))
    return data, spacing, mode, stride, timed, axis, draw(st.randoms(use_true_random=False))


@pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")
@settings(max_examples=examples(40), deadline=None)
@given(case=cases())
def test_the_readout_is_the_t_index_and_the_series_value_at_that_voxel(case):
    data, spacing, mode, stride, timed, axis, rnd = case
    t = data.shape[0]
    times = [0.25 * s for s in range(t)] if timed else None
    series = _series(data, spacing, times, "s" if timed else None)
    threshold = {"threshold": 0.5} if mode == "first_hit" else {}
    cv = chronocl.integrate(
        series, f"0:{t}:{stride}", mode, engine="numpy", value_range=(0.0, 50.0), **threshold
    )
    nz, ny, nx = cv.shape
    index = rnd.randrange({"x": nx, "y": ny, "z": nz}[axis])
    sl = parse_slice(f"{axis}={index}", cv.shape)
    won = slice_steps(cv, sl)
    rows, cols = won.shape
    row, col = rnd.randrange(rows), rnd.randrange(cols)
    x, y, z = slice_voxel(sl, cv.shape, col, row)
    assert {"x": x, "y": y, "z": z}[axis] == index
    assert won[row, col] == cv.t_index[z, y, x]  # the map shows the voxel the read-out reads

    got = slice_value(cv, series, x, y, z)
    assert got.voxel == (x, y, z)
    assert got.position == pytest.approx((x * spacing[0], y * spacing[1], z * spacing[2]))
    step = int(cv.t_index[z, y, x])
    if step < 0:
        assert got.step is None and got.value is None and got.time is None
        assert "no step won" in got.describe()
        return
    assert got.step == step and step in cv.steps
    assert got.value == float(data[step, z, y, x])
    assert got.time == (times[step] if timed else step)
    assert got.time_text == (f"{times[step]:g} s" if timed else str(step))
    # the winner is what the mode says it is, at this voxel over the window's steps
    window = list(cv.steps)
    values = data[window, z, y, x]
    if mode == "max":
        assert got.value == values.max()
    elif mode == "min":
        assert got.value == values.min()


def test_the_step_map_takes_a_slice_spec_and_converts_only_its_plane(max_cv):
    """`step_map` parses its slice as every function here does (it passed the text on, and
    a winner mode raised AttributeError), and a picture converts only its plane to float."""
    import tracemalloc

    from chronocl.render.slices import slice_colours

    got = step_map(max_cv, "z=1")
    assert got is not None and got.shape[2] == 3
    big = chronocl.Chronovolume(
        rgba=np.zeros((96, 96, 96, 4), np.uint8), t_index=None, metadata=max_cv.metadata
    )
    tracemalloc.start()
    slice_colours(big, "z=3")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < big.rgba.nbytes  # a plane's worth, not the volume as float32 (4x its bytes)


def test_a_mode_without_t_index_reads_no_step():
    data = np.random.default_rng(1).random((3, 4, 5, 6), dtype=np.float32)
    series = _series(data, (1.0, 2.0, 3.0))
    cv = chronocl.integrate(series, "0:3", "alpha", engine="numpy")
    got = slice_value(cv, series, 5, 4, 3)
    assert got.step is None and got.position == (5.0, 8.0, 9.0)
    assert slice_steps(cv, "z=1") is None and step_map(cv, "z=1") is None
    with pytest.raises(ChronoclError, match="outside the volume"):
        slice_value(cv, series, 6, 0, 0)


@pytest.fixture(scope="module")
def max_cv():
    data = np.random.default_rng(7).random((5, 7, 9, 11), dtype=np.float32)
    series = _series(data, (1.0, 2.5, 0.5), [0.5 * s for s in range(5)], "s")
    cv = chronocl.integrate(series, "0:5", "max", engine="numpy", time_tf="rgb")
    rng = np.random.default_rng(3)
    alpha = rng.random(cv.shape, dtype=np.float32)
    rgb = rng.random((*cv.shape, 3), dtype=np.float32) * alpha[..., None]  # premultiplied
    cv.rgba = np.concatenate([rgb, alpha[..., None]], axis=-1)
    cv.t_index[0, 0, :3] = -1  # nothing won there
    return cv


@pytest.mark.parametrize(
    ("spec", "size", "background"),
    [("z=3", (96, 80), "black"), ("y=0", (61, 97), "#3080c0"), ("x=10", (64, 64), "white")],
)
def test_the_pictures_pixels_are_the_slice_composited(max_cv, spec, size, background):
    from chronocl.render.views import parse_color

    cv = max_cv
    sl = parse_slice(spec, cv.shape)
    bg = np.asarray(parse_color(background), dtype=np.float64)
    plane = _plane_oracle(cv.rgba.astype(np.float64), sl.axis, sl.index)
    want = np.round(np.clip(plane[..., :3] + (1 - plane[..., 3:]) * bg, 0, 1) * 255)
    assert np.array_equal(slice_colours(cv, sl, background), want.astype(np.uint8))

    # the voxel grid drawn in its box: each voxel spacing wide, the aspect ratio kept
    rows, cols = plane.shape[:2]
    sp = dict(zip("xyz", cv.spacing, strict=True))
    across, up = sp[sl.across], sp[sl.up]
    x0, y0, pw, ph = fit_box((rows, cols), (across, up), size)
    assert pw == size[0] or ph == size[1]
    ratio = (cols * across) / (rows * up)  # width over height in data units
    assert ph == round(pw / ratio) if pw == size[0] else pw == round(ph * ratio)
    image = render_slice(cv, spec, size, background=background, name="grid").array
    w, h = size
    assert image.shape[1] == 2 * w  # colours and the step map side by side
    r = (np.arange(ph) * rows) // ph
    c = (np.arange(pw) * cols) // pw
    drawn = want.astype(np.uint8)[r[:, None], c[None, :]]  # nearest voxel per pixel
    # the panel lies under the title and caption bands: where the drawn grid is found whole
    tops = [
        t
        for t in range(image.shape[0] - h + 1)
        if np.array_equal(image[t + y0 : t + y0 + ph, x0 : x0 + pw], drawn)
    ]
    assert tops, "the composited slice is not in the picture"
    top = tops[0]
    assert top == slice_picture(cv, spec, size, background, name="grid").layout.pictures[0][1]
    bg8 = np.round(bg * 255).astype(np.uint8)
    panel = image[top : top + h, :w]
    outside = np.ones((h, w), bool)
    outside[y0 : y0 + ph, x0 : x0 + pw] = False
    assert (panel[outside] == bg8).all()  # the panel around the picture is the background

    # the step map beside it: each voxel its winning step's time colour; none, or a winner
    # with no opacity: the background
    colours = step_colours(cv)
    won = _plane_oracle(cv.t_index, sl.axis, sl.index)
    seen = _plane_oracle(cv.float_rgba()[..., 3], sl.axis, sl.index) > 0
    expect = np.empty((rows, cols, 3), np.uint8)
    expect[...] = bg8
    for s, colour in colours.items():
        expect[(won == s) & seen] = colour
    steps_picture = image[top + y0 : top + y0 + ph, w + x0 : w + x0 + pw]
    assert np.array_equal(steps_picture, expect[r[:, None], c[None, :]])


def test_bad_slices_are_one_line(max_cv):
    for bad, needle in [
        ("q=4", "must be x=N, y=N or z=N"),
        ("z", "must be x=N"),
        ("z=7", "outside the volume: z runs 0..6"),
        ("x=-1", "outside the volume: x runs 0..10"),
        (("y", 1.5), "whole voxel index"),
        (3, "must be x=N"),
    ]:
        with pytest.raises(ChronoclError, match=needle) as err:
            render_slice(max_cv, bad)
        assert "\n" not in str(err.value)
    assert parse_slice(" Z = 6 ", max_cv.shape) == Slice("z", 6)
    assert parse_slice(("x", np.int64(2))) == Slice("x", 2)


@pytest.fixture(scope="module")
def vortex(tmp_path_factory):
    path = tmp_path_factory.mktemp("slices") / "v.zarr"
    assert cli("generate", "vortex", path, "--shape", "20x16x12", "--steps", "6").returncode == 0
    return path


def test_cli_writes_the_slice_picture_render_slice_draws(tmp_path, vortex):
    from PIL import Image as PILImage

    out, saved = tmp_path / "s.png", tmp_path / "cv.zarr"
    result = cli(
        "render", vortex, "--window", "0:6", "--mode", "max", "--slice", "z=5", "--engine",
        "numpy", "--size", "96x80", "--background", "#202020", "-o", out,
        "--save-chronovolume", saved,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    image = PILImage.open(out)
    assert image.width == 2 * 96 and image.height > 80  # two panels; title, captions, legends
    cv = chronocl.Chronovolume.load(saved)
    again = render_slice(cv, "z=5", (96, 80), background="#202020")
    assert np.array_equal(np.asarray(image.convert("RGB")), again.array)
    assert image.text.get("Title", "").startswith("v.zarr: steps 0:6")


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--slice", "q=4"], "slice 'q=4' must be x=N, y=N or z=N"),
        (["--slice", "z=12"], "slice z=12 is outside the volume: z runs 0..11"),
        (["--slice", "z=3", "--mode", "max,alpha"], "--slice draws one mode"),
        (["--slice", "z=3", "--turntable", "t.gif"], "--slice draws a picture, not a turn"),
        (["--slice", "z=3", "--state", "s.json"], "--slice does not combine with --state"),
    ],
)
def test_cli_bad_slices_exit_2_with_one_line(tmp_path, vortex, args, needle):
    out = tmp_path / "bad.png"
    result = cli("render", vortex, "--engine", "numpy", "-o", out, *args)
    assert_one_line_error(result, needle)
    assert not out.exists()


def test_the_viewers_slice_reply_reads_the_voxel_under_the_point(max_cv):
    """The viewer's `slice` reply (chronocl.viewer.slicing): the picture render_slice draws at
    the view's size and background, where the grid lies, and at a point of the grid the
    read-out: the t_index there and the series' value at that voxel and step."""
    import base64
    import io
    import json

    from PIL import Image as PILImage

    from chronocl.viewer.datasets import Dataset
    from chronocl.viewer.slicing import slice_reply
    from chronocl.viewer.view_state import ViewState

    data = np.random.default_rng(7).random((5, 7, 9, 11), dtype=np.float32)
    series = _series(data, (1.0, 2.5, 0.5), [0.5 * s for s in range(5)], "s")
    cv = max_cv  # integrated from this series, its RGBA replaced
    state = ViewState(size=(96, 80), background="white")
    msg = {"type": "slice", "id": 3, "view": 0, "slice": "y=4", "u": 0.99, "v": 0.0}
    reply = slice_reply(msg, 0, state, cv, Dataset("grid", series))
    json.dumps(reply)  # it goes to the page as it is
    png = base64.b64decode(reply["png"].split(",", 1)[1])
    drawn = np.asarray(PILImage.open(io.BytesIO(png)).convert("RGB"))
    want = render_slice(cv, "y=4", (96, 80), background="white", name="grid").array
    assert np.array_equal(drawn, want)
    assert reply["grid"] == {"rows": 7, "cols": 11, "across": "x", "up": "z"}
    assert reply["box"] == list(fit_box((7, 11), (1.0, 0.5), (96, 80)))
    read = reply["readout"]
    assert read["voxel"] == {"x": 10, "y": 4, "z": 6}  # right edge, top row: the highest z
    step = int(cv.t_index[6, 4, 10])
    assert read["step"] == step and read["value"] == float(data[step, 6, 4, 10])
    assert read["time"] == f"{0.5 * step:g} s"
    assert read["position"] == {"x": 10.0, "y": 10.0, "z": 3.0}
    with pytest.raises(ChronoclError, match="outside the volume"):
        slice_reply({"slice": "y=9"}, 0, state, cv, Dataset("grid", series))
    with pytest.raises(ChronoclError, match="in \\[0, 1\\]"):
        slice_reply({"slice": "y=4", "u": 2, "v": 0}, 0, state, cv, Dataset("grid", series))
    assert slice_reply({"slice": "z=0"}, 0, state, cv, Dataset("grid", series))["readout"] is None
    # the page gives its panel's room: each of the two pictures takes half its width, at the
    # view's aspect (96x80), the captions and legends below
    sized = slice_reply({"slice": "y=4", "size": [400, 900]}, 0, state, cv, Dataset("g", series))
    assert sized["size"][0] == 400 and sized["grid"] == reply["grid"]
    want = render_slice(cv, "y=4", (200, 167), background="white", name="g").array
    png = base64.b64decode(sized["png"].split(",", 1)[1])
    assert np.array_equal(np.asarray(PILImage.open(io.BytesIO(png)).convert("RGB")), want)


def test_a_real_server_answers_a_slice_request_with_the_winner_under_the_point(tmp_path):
    """The `slice` message over a real viewer's socket: the render thread answers it from the
    view's full-resolution chronovolume (max here), the read-out's step is that chronovolume's
    t_index at the voxel and its value the series' raw value there; a bad slice is one line."""
    pytest.importorskip("starlette")
    from chronocl.data.series import open_series

    from .viewer_helpers import Client, make_stores, start_server

    stores = make_stores(tmp_path)
    server = start_server(stores)
    try:
        client = Client(server)
        client.open(0, size=(96, 96))
        window = {"t0": 2, "t1": 9}
        rid = client.send({"type": "update", "views": [{"mode": "max"}], "window": window})
        client.frame_for(rid)
        rid = client.send({"type": "slice", "view": 0, "slice": "z=16", "u": 0.3, "v": 0.6})
        _, reply = client.wait("slice", rid)
        assert reply["png"].startswith("data:image/png;base64,") and reply["slice"] == "z=16"
        got = reply["readout"]
        x, y, z = (got["voxel"][a] for a in "xyz")
        assert z == 16
        series = open_series(stores[0])
        cv = chronocl.integrate(series, "2:9", mode="max")
        step = int(cv.t_index[z, y, x])
        assert got["step"] == step >= 0
        assert got["value"] == pytest.approx(float(series.read_region(step, z, y, x)))
        # a pointer moving over the picture: the read-out alone, no picture drawn
        msg = {"type": "slice", "view": 0, "slice": "z=16", "u": 0.3, "v": 0.6, "picture": False}
        rid = client.send(msg)
        _, alone = client.wait("slice", rid)
        assert "png" not in alone and alone["readout"] == got
        rid = client.send({"type": "slice", "view": 0, "slice": "q=4"})
        _, error = client.wait("error", rid)
        assert "\n" not in error["message"] and "q=4" in error["message"]
        # a probe pinned at the same point of the slice: v(t) at the voxel the read-out named
        rid = client.send({"type": "probe", "view": 0, "slice": "z=16", "u": 0.3, "v": 0.6})
        _, probe = client.wait("probe", rid)
        assert probe["voxel"] == got["voxel"] and probe["pinned"] == "slice"
        curve = [float(series.read_region(t, z, y, x)) for t in range(series.n_steps)]
        assert probe["values"] == pytest.approx(curve) and probe["window"] == list(range(2, 9))
        bad_probes = (
            ({}, "a view's pixel"),
            ({"slice": "z=16"}, "one of them"),  # no point on it
            ({"slice": "z=16", "u": 0.3, "v": 0.6, "x": 0.5, "y": 0.5}, "one of them"),
            ({"u": 0.3, "v": 0.6}, "one of them"),
            ({"x": 0.5}, "one of them"),
            ({"x": 0.5, "y": 0.5, "x2": 0.6}, "one of them"),
            ({"slice": "z=99", "u": 0, "v": 0}, "z=99"),
        )
        for bad, needle in bad_probes:
            rid = client.send({"type": "probe", "view": 0, **bad})
            _, error = client.wait("error", rid)
            assert "\n" not in error["message"] and needle in error["message"], error
        client.close()
    finally:
        server.stop()
