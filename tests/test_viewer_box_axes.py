"""The box's axes (chronocl/viewer/box_axes.py): with the box on, each view's frame header
carries three labelled edges of the volume's box whose ticks are 1-2-5 values of the data's
coordinates (voxel index times the series' spacing, one axis not 1) within its extent, placed
where `probe.project` puts those points under the view's camera; an axis seen end-on has none,
the edges chosen lie towards the panel's lower left, and the saved picture draws them. With a
clip plane they label the part it keeps (none of their ticks where it cuts the box away), and
an edge along the picture's border keeps its labels (on its inner side where the outer is off
the picture)."""

from __future__ import annotations

import io
import itertools
import math
import urllib.request

import numpy as np
import pytest

from chronocl.core.ticks import tick_text
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera
from chronocl.viewer.box_axes import box_axes, draw_axes
from chronocl.viewer.probe import project

SHAPE_ZYX = (12, 16, 24)
SPACING = (0.5, 1.0, 2.5)  # dx, dy, dz


def geometry_only(shape_zyx=SHAPE_ZYX, spacing=SPACING) -> Chronovolume:
    """A chronovolume with the series' box (all `project` and `box_axes` read of it)."""
    return Chronovolume(
        rgba=np.zeros((*shape_zyx, 4), np.float32),
        metadata={"spacing": dict(zip("xyz", spacing, strict=True))},
    )


def is_nice(step: float) -> bool:
    mantissa = step / 10 ** math.floor(math.log10(step) + 1e-9)
    return any(math.isclose(mantissa, m, rel_tol=1e-6) for m in (1, 2, 5))


def check_axes(edges, cv, camera, size, dims, spacing) -> None:
    """Every tick a 1-2-5 multiple within its axis' voxel centres, labelled as the legends
    label theirs, at `project` of its point on its edge."""
    for edge in edges:
        a = "xyz".index(edge["axis"])
        values = [t["value"] for t in edge["ticks"]]
        assert values, edge
        assert all(0 <= v <= (dims[a] - 1) * spacing[a] + 1e-9 for v in values)
        steps = np.diff(values)
        if len(values) > 1:
            np.testing.assert_allclose(steps, steps[0], rtol=1e-6)
            assert is_nice(float(steps[0]))
        step = float(steps[0]) if len(values) > 1 else 1.0
        for tick in edge["ticks"]:
            assert float(tick["value"] / step).is_integer() or len(values) == 1
            assert tick["label"] == tick_text(tick["value"], step)
            # The tick's point: voxel index value / spacing on this axis, on the edge.
            where = [0.0 if p < 0.5 else 1.0 for p in edge_corner(edge, cv, camera, size)]
            where[a] = (tick["value"] / spacing[a] + 0.5) / dims[a]
            at = project(cv, camera, size, tuple(where))
            assert at is not None
            np.testing.assert_allclose([tick["x"], tick["y"]], at, atol=2e-5)


def projected_corners(cv, camera, size) -> np.ndarray:
    """The box's 8 corners on the panel (fractions, beyond 0..1 off it)."""
    from chronocl.render.camera import to_panel, world_extent

    extent = world_extent(cv.shape, cv.spacing)
    corners = np.array(list(itertools.product((-0.5, 0.5), repeat=3))) * extent
    return to_panel(camera, extent, size, corners)


def edge_corner(edge, cv, camera, size) -> list[float]:
    """The box fractions (x, y, z) of the corner the edge starts at (the one whose projection
    is its `from`; corners may lie off the panel, where `project` gives None)."""
    from chronocl.render.camera import to_panel, world_extent

    extent = world_extent(cv.shape, cv.spacing)
    a = "xyz".index(edge["axis"])
    starts = [c for c in itertools.product((0.0, 1.0), repeat=3) if c[a] == 0.0]
    at = to_panel(camera, extent, size, (np.array(starts) - 0.5) * extent)
    return list(starts[int(np.argmin(np.hypot(*(at - edge["from"]).T)))])


@pytest.mark.parametrize(
    "camera",
    [
        Camera(),
        Camera(azimuth=125.0, elevation=35.0),
        Camera(azimuth=-60.0, elevation=-25.0, projection="orthographic"),
    ],
)
def test_ticks_are_nice_values_at_the_projected_points(camera):
    cv = geometry_only()
    size = (480, 360)
    dims = cv.dims
    edges = box_axes(cv, camera, size, dims, SPACING)
    assert sorted(e["axis"] for e in edges) == ["x", "y", "z"]
    check_axes(edges, cv, camera, size, dims, SPACING)
    # z's voxels are 2.5 apart: its ticks reach past its 12 voxels' count, x's (0.5) stay under
    z = next(e for e in edges if e["axis"] == "z")
    x = next(e for e in edges if e["axis"] == "x")
    assert max(t["value"] for t in z["ticks"]) > SHAPE_ZYX[0]
    assert max(t["value"] for t in x["ticks"]) < SHAPE_ZYX[2]
    corners = projected_corners(cv, camera, size) * size
    for e in edges:
        assert math.isclose(math.hypot(*e["out"]), 1.0, rel_tol=1e-4)
        # On the box's outline, `out` away from it: every corner on the edge's inner side.
        assert ((corners - np.multiply(e["from"], size)) @ e["out"] < 0.05).all(), e["axis"]


def test_the_edges_lie_towards_the_lower_left_and_an_end_on_axis_has_none():
    cv = geometry_only()
    size = (400, 400)
    front = Camera(azimuth=0.0, elevation=0.0, projection="orthographic")
    edges = {e["axis"]: e for e in box_axes(cv, front, size, cv.dims, SPACING)}
    assert set(edges) == {"x", "y"}  # z points at the viewer
    x, y = edges["x"], edges["y"]
    assert x["from"][1] > 0.5 and x["to"][1] > 0.5 and x["out"] == [0.0, 1.0]  # bottom, below
    assert y["from"][0] < 0.5 and y["to"][0] < 0.5 and y["out"] == [-1.0, 0.0]  # left, left of it
    assert x["from"][0] < x["to"][0] and y["from"][1] > y["to"][1]  # 0 at the lower left


def tick_fractions(edge, tick, cv, camera, size, dims, spacing, bounds) -> np.ndarray:
    """The box fractions (x, y, z) of `tick`'s point: its value along its axis, on one of the
    edges of the box `bounds` ((lo, hi) box fractions per axis) along it, the one where
    `project` puts the tick."""
    a = "xyz".index(edge["axis"])
    found = []
    for others in itertools.product(*[bounds[k] for k in range(3) if k != a]):
        where = list(others)
        where.insert(a, (tick["value"] / spacing[a] + 0.5) / dims[a])
        at = project(cv, camera, size, tuple(where))
        if at is not None and np.hypot(*np.subtract(at, [tick["x"], tick["y"]])) < 2e-5:
            found.append(where)
    assert found, (edge["axis"], tick)
    return np.array(found[0])


def test_the_axes_label_the_part_an_axis_aligned_clip_plane_keeps():
    cv = geometry_only()
    size = (480, 360)
    camera = Camera(azimuth=40.0, elevation=25.0)
    dims = cv.dims
    # x >= the box's middle kept: x's ticks from the plane's data x (voxel 11.5 of 24, times
    # 0.5) to the last voxel's; every tick on the kept half's edges
    edges = box_axes(cv, camera, size, dims, SPACING, (1.0, 0.0, 0.0, 0.0))
    assert sorted(e["axis"] for e in edges) == ["x", "y", "z"]
    x = next(e for e in edges if e["axis"] == "x")
    values = [t["value"] for t in x["ticks"]]
    assert values and min(values) >= 11.5 * SPACING[0], values
    assert max(values) <= (dims[0] - 1) * SPACING[0]
    whole = next(e for e in box_axes(cv, camera, size, dims, SPACING) if e["axis"] == "x")
    assert min(t["value"] for t in whole["ticks"]) == 0  # (unclipped: from the first voxel)
    bounds = [(0.5, 1.0), (0.0, 1.0), (0.0, 1.0)]
    for edge in edges:
        for tick in edge["ticks"]:
            where = tick_fractions(edge, tick, cv, camera, size, dims, SPACING, bounds)
            assert where[0] >= 0.5 - 1e-9, (edge["axis"], tick)
    # The x edge runs from the plane (x fraction 0.5) to the box's high x face, at a corner of
    # the kept half.
    for end, fraction in ((x["from"], 0.5), (x["to"], 1.0)):
        corners = [project(cv, camera, size, (fraction, y, z)) for y in (0, 1) for z in (0, 1)]
        assert min(np.hypot(*np.subtract(c, end)) for c in corners) < 2e-5, (end, fraction)
    # A plane that keeps nothing: no axes; one that keeps all: the whole box's.
    assert box_axes(cv, camera, size, dims, SPACING, (1.0, 0.0, 0.0, 1.0)) == []
    assert box_axes(cv, camera, size, dims, SPACING, (1.0, 0.0, 0.0, -1.0)) == box_axes(
        cv, camera, size, dims, SPACING
    )


def test_no_labelled_tick_lies_where_an_oblique_clip_plane_cuts_the_box_away():
    from chronocl.render.camera import world_extent
    from chronocl.render.raycaster import clip_plane
    from chronocl.viewer.box_axes import visible_bounds

    cv = geometry_only()
    size = (480, 360)
    dims = cv.dims
    extent = world_extent(cv.shape, cv.spacing)
    clip = (1.0, 1.0, 0.0, 0.5)
    *n, d = clip_plane(clip, extent)
    lo, hi = visible_bounds(extent, clip)
    bounds = list(zip(lo / extent + 0.5, hi / extent + 0.5, strict=True))
    assert all(b - a < 1 for a, b in bounds[:2])  # the kept part's box is smaller in x and y
    for camera in (Camera(), Camera(azimuth=-130.0, elevation=-30.0)):
        edges = box_axes(cv, camera, size, dims, SPACING, clip)
        assert edges and sum(len(e["ticks"]) for e in edges) >= 4
        for edge in edges:
            for tick in edge["ticks"]:
                where = tick_fractions(edge, tick, cv, camera, size, dims, SPACING, bounds)
                world = (where - 0.5) * extent
                assert world @ n + d >= -1e-9, (camera, edge["axis"], tick)


def labels_drawn(edges, size) -> dict[str, int]:
    """Per axis, how many of its tick labels `draw_axes` draws on a black panel of `size`:
    light grey ink just off each tick on its edge's `out` side."""
    w, h = size
    drawn = draw_axes(np.zeros((h, w, 3), np.uint8), edges)
    grey = (drawn > 180).all(axis=2)
    counts = {}
    for edge in edges:
        n = 0
        for tick in edge["ticks"]:
            at = np.array([tick["x"] * w, tick["y"] * h]) + np.multiply(edge["out"], 14)
            x, y = np.round(at).astype(int)
            n += bool(grey[max(0, y - 7) : y + 8, max(0, x - 7) : x + 8].any())
        counts[edge["axis"]] = n
    return counts


@pytest.mark.parametrize(
    "camera, size, spacing, dims, want",
    [
        # the four-view panel of the browser test: x's best edge runs along the top border
        (
            Camera(
                zoom=1.2,
                focus=(-0.2333333, -0.3333333, -0.4166667, 0.25, 0.4, 0.4166667),
            ),
            (351, 171),
            (0.5, 1.0, 2.5),
            (32, 24, 12),
            {"x": 2, "y": 2, "z": 1},
        ),
        # seen from the front, magnified: the box's lower edge a few pixels above the bottom
        (
            Camera(azimuth=0.0, elevation=0.0, projection="orthographic", zoom=2.1),
            (400, 300),
            SPACING,
            (24, 16, 12),
            {"x": 2, "y": 2},
        ),
    ],
)
def test_an_edge_along_the_pictures_border_keeps_its_labels(camera, size, spacing, dims, want):
    cv = geometry_only(dims[::-1], spacing)
    edges = box_axes(cv, camera, size, dims, spacing)
    assert {e["axis"] for e in edges} == set(want)
    got = labels_drawn(edges, size)
    assert all(got[a] >= k for a, k in want.items()), (got, edges)


def test_the_saved_picture_draws_the_labels():
    cv = geometry_only()
    camera = Camera()
    edges = box_axes(cv, camera, (320, 240), cv.dims, SPACING)
    panel = np.zeros((240, 320, 3), np.uint8)
    drawn = draw_axes(panel, edges)
    assert drawn.shape == panel.shape and drawn.dtype == np.uint8
    grey = (drawn > 180).all(axis=2)  # the tick labels' light grey
    assert grey.sum() > 50
    for edge in edges:  # near each kept tick label
        t = edge["ticks"][-1]
        x, y = round(t["x"] * 320), round(t["y"] * 240)
        assert drawn[max(0, y - 25) : y + 25, max(0, x - 25) : x + 25].any()
    assert draw_axes(panel, None) is panel


# --------------------------------------------------------------------------- over the socket

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from .viewer_helpers import Client, serving  # noqa: E402


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    from chronocl.data import synthetic
    from chronocl.data.series import TimeSeries

    root = tmp_path_factory.mktemp("viewer-axes")
    data = np.stack(list(synthetic.steps("vortex", 6, SHAPE_ZYX)))
    path = root / "aniso.zarr"
    TimeSeries.from_array(data, spacing=SPACING, source="aniso").save(path)
    yield from serving([path], gl_current=True)


def fetch(server, url: str) -> bytes:
    req = urllib.request.Request(server.base + url, headers={"X-Chronocl-Token": server.token})
    with urllib.request.urlopen(req, timeout=30) as r:
        return r.read()


def test_the_frame_header_carries_each_views_axes_with_the_box_on(server, tmp_path):
    from PIL import Image

    client = Client(server)
    try:
        size = (300, 200)
        _, (_, header, _) = client.open(0, size=size)
        assert header["axes"] is None  # the box is off
        cam = {"azimuth": 40.0, "elevation": 25.0, "zoom": 1.0, "projection": "perspective"}
        rid = client.send(
            {
                "type": "update",
                "outline": True,
                "camera": cam,
                "views": [{"mode": "alpha"}, {"mode": "max", "camera": {**cam, "azimuth": 160.0}}],
            }
        )
        _, header, _ = client.frame_for(rid)
        while header["id"] != rid or header["refining"]:
            _, header, _ = client.frame_for(rid)
        axes = header["axes"]
        assert len(axes) == 2 and axes[0] != axes[1]  # each view under its own camera
        cv = geometry_only()
        focus = tuple(header["focus"])
        for view, azimuth in ((0, 40.0), (1, 160.0)):
            camera = Camera(**{**cam, "azimuth": azimuth}, focus=focus)
            assert sorted(e["axis"] for e in axes[view]) == ["x", "y", "z"]
            check_axes(axes[view], cv, camera, size, cv.dims, SPACING)

        # The saved PNG carries the same labels: light grey ink beside each tick's point.
        rid = client.send({"type": "save", "what": "image"})
        _, dl = client.wait("download", rid)
        png = fetch(server, dl["url"])
        (tmp_path / "box-axes-saved.png").write_bytes(png)
        x0, y0, w, h = dl["layout"]["pictures"][0]
        picture = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))[y0 : y0 + h, x0 : x0 + w]
        assert (w, h) == size
        for edge in axes[0]:
            for tick in edge["ticks"][1:]:  # (a zero at a shared corner may be left out)
                at = np.array([tick["x"] * w, tick["y"] * h]) + np.multiply(edge["out"], 14)
                x, y = np.clip(at.round().astype(int), 8, [w - 9, h - 9])
                assert (picture[y - 8 : y + 9, x - 8 : x + 9].min(axis=-1) > 200).any(), tick

        # A clip plane keeping z >= the middle: each view's z ticks from the plane on (its
        # data z: voxel 5.5 of 12, times 2.5).
        rid = client.send({"type": "update", "clip": {"normal": [0, 0, 1], "offset": 0.0}})
        _, header, _ = client.frame_for(rid)
        while header["id"] != rid or header["refining"]:
            _, header, _ = client.frame_for(rid)
        for view in header["axes"]:
            z = next(e for e in view if e["axis"] == "z")
            assert z["ticks"] and min(t["value"] for t in z["ticks"]) >= 5.5 * SPACING[2]

        rid = client.send({"type": "update", "outline": False})
        assert client.frame_for(rid)[1]["axes"] is None
    finally:
        client.close()
