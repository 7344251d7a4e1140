"""The first picture frames what is visible: an off-centre small plume fills the image by
default, `frame="box"` / `--frame box` frames the whole box as before, zoom is relative to the
visible region, the camera orbits about its centre, an all-transparent volume keeps the box."""

from __future__ import annotations

import sys

import numpy as np
import pytest

import chronocl
from chronocl import Camera, render
from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import world_extent
from chronocl.render.framing import framed, visible_box

SIZE = (96, 96)


def plume(steps: int = 4, shape=(28, 48, 32)) -> np.ndarray:
    """A small plume rising in a corner of a tall box (the held-out 64x96x56 plume, halved):
    a blob near x = 3/4, low in y, near the back in z, stretching upwards over time."""
    nz, _, nx = shape
    z, y, x = np.meshgrid(*[np.arange(n, dtype=np.float32) for n in shape], indexing="ij")
    frames = []
    for t in range(steps):
        r2 = (
            ((z - 0.25 * nz) / 3) ** 2
            + ((y - 10 - 2 * t) / (4 + t)) ** 2
            + ((x - 0.75 * nx) / 3) ** 2
        )
        frames.append(np.exp(-r2))
    return np.stack(frames).astype(np.float32)


@pytest.fixture(scope="module")
def plume_cv() -> Chronovolume:
    series = chronocl.TimeSeries.from_array(plume(), source="plume")
    # The series' recorded range: a small plume off-centre in its box (fitted, it fills more).
    return chronocl.integrate(
        series, "0:4", "alpha", engine="numpy", data_tf=chronocl.DataTF(value_range="global")
    )


def drawn_fraction(image: np.ndarray) -> tuple[float, float, tuple[float, float]]:
    """(width, height) of the drawn pixels' bounding box as fractions of the image, and its
    centre in fractions."""
    ys, xs = np.nonzero(image.max(axis=2) > 12)
    h, w = image.shape[:2]
    width, height = (xs.max() - xs.min() + 1) / w, (ys.max() - ys.min() + 1) / h
    return width, height, ((xs.max() + xs.min()) / 2 / w, (ys.max() + ys.min()) / 2 / h)


def test_the_visible_region_fills_the_image_the_box_does_not(plume_cv):
    visible = render(plume_cv, Camera(), SIZE, jitter=False).array
    box = render(plume_cv, Camera(frame="box"), SIZE, jitter=False).array
    vw, vh, (cx, cy) = drawn_fraction(visible)
    bw, bh, _ = drawn_fraction(box)
    assert max(vw, vh) > 0.6, (vw, vh)  # the plume is most of the picture
    assert vw * vh > 4 * bw * bh, (vw, vh, bw, bh)  # not the speck it is in the box
    assert abs(cx - 0.5) < 0.12 and abs(cy - 0.5) < 0.12  # and in the middle
    # zoom is relative to the visible region: 0.5 shows it at about half the size
    hw, hh, _ = drawn_fraction(render(plume_cv, Camera(zoom=0.5), SIZE, jitter=False).array)
    assert 0.35 < max(hw, hh) / max(vw, vh) < 0.65


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_the_camera_orbits_about_the_visible_centre(plume_cv, projection):
    box = visible_box(plume_cv)
    extent = world_extent(plume_cv.shape, plume_cv.spacing)
    assert box is not None and (box[3:] - box[:3] < 0.5 * extent).all()  # small, off-centre
    centre = np.append((box[:3] + box[3:]) / 2, 1.0)
    for azimuth, elevation in ((0, 0), (75, 30), (200, -40), (330, 85)):
        camera = framed(Camera(azimuth, elevation, projection=projection), [plume_cv])
        assert camera.focus is not None
        view, proj = camera.matrices(extent, 1.0)
        ndc = proj @ view @ centre
        np.testing.assert_allclose(ndc[:2] / ndc[3], 0.0, atol=1e-9)
        # Every corner of the box stays between the near and far planes.
        corners = np.array([[sx, sy, sz, 2] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        clip = (proj @ view @ (corners * np.append(extent / 2, 0.5)).T).T
        depth = clip[:, 2] / clip[:, 3]
        assert (depth > -1).all() and (depth < 1).all()


def test_transparent_or_full_volumes_keep_the_box_framing():
    rgba = np.zeros((8, 10, 12, 4), np.float32)
    empty = Chronovolume(rgba)
    assert visible_box(empty) is None
    assert framed(Camera(), [empty]) == Camera()
    image = render(empty, Camera(), (32, 32)).array
    assert image.max() == 0  # drawn, black
    full = Chronovolume(np.full((8, 10, 12, 4), 0.5, np.float32))
    assert framed(Camera(), [full]).focus is None  # exactly the box's matrices
    faint = rgba.copy()
    faint[2:4, 3:5, 4:6, 3] = 0.001  # faint, but all there is: framed
    assert framed(Camera(), [Chronovolume(faint)]).focus is not None
    assert framed(Camera(frame="box"), [Chronovolume(faint)]).focus is None


def test_bad_framing_is_refused():
    with pytest.raises(UnknownNameError, match=r"choose visible .* or box"):
        Camera(frame="middle")
    with pytest.raises(InvalidParameterError, match="x0 < x1"):
        Camera(focus=(0, 0, 0, 0, 1, 1))


def test_cli_frames_the_visible_region_unless_told_box(tmp_path, monkeypatch, capsys):
    from PIL import Image as PILImage

    from chronocl.cli import main

    store = tmp_path / "plume.zarr"
    chronocl.TimeSeries.from_array(plume(2), source="plume").save(store)

    def run(*args: str) -> int:
        argv = ["chronocl", "render", str(store), "--engine", "numpy", "--size", "64x64"]
        # Without the box outline, which spans the whole box whatever is framed.
        monkeypatch.setattr(sys, "argv", [*argv, "--no-outline", *args])
        with pytest.raises(SystemExit) as info:
            main()
        return info.value.code or 0

    assert run("-o", str(tmp_path / "v.png")) == 0
    assert run("-o", str(tmp_path / "b.png"), "--frame", "box") == 0
    sizes = []
    for name in ("v.png", "b.png"):
        panel = np.asarray(PILImage.open(tmp_path / name).convert("RGB"))[:64]
        w, h, _ = drawn_fraction(panel)
        sizes.append(w * h)
    assert sizes[0] > 4 * sizes[1]
    capsys.readouterr()
    assert run("-o", str(tmp_path / "x.png"), "--frame", "middle") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "choose visible" in err[0] and not (tmp_path / "x.png").exists()


def test_viewer_frames_the_visible_region_and_again_on_reset(tmp_path):
    """The viewer frames what is visible at the first frame, keeps that framing while the
    window moves (no jumping), and frames what is visible now at a camera reset."""
    import io

    from PIL import Image as PILImage

    from chronocl.render.views import raycaster
    from chronocl.viewer.server import ViewerServer

    from .viewer_helpers import Client

    raycaster()  # the process's GL context stays current in this thread, as in other tests
    store = tmp_path / "plume.zarr"
    times = [f"2024-01-01T{6 + 2 * t:02d}:00:00" for t in range(4)]
    chronocl.TimeSeries.from_array(plume(), times=times, source="plume").save(store)
    server = ViewerServer([store], engine="numpy")
    server.start()
    client = Client(server)
    try:

        def centre_and_size(got) -> tuple[float, float]:
            image = np.asarray(PILImage.open(io.BytesIO(got[2][0])).convert("RGB"))
            w, h, (_, cy) = drawn_fraction(image)
            return cy, max(w, h)

        ds, first = client.open(0, size=(96, 96))
        assert ds["time_labels"] == [f"2024-01-01 {6 + 2 * t:02d}:00" for t in range(4)]
        _, size = centre_and_size(first)
        assert size > 0.6  # the plume fills the view
        rid = client.send({"type": "update", "window": {"t0": 0, "t1": 1}})
        kept, _ = centre_and_size(client.frame_for(rid))
        camera = {"azimuth": 30.0, "elevation": 20.0, "zoom": 1.2}
        rid = client.send({"type": "update", "camera": camera, "refocus": True})
        again, _ = centre_and_size(client.frame_for(rid))
        assert kept > 0.58  # the oldest step sits low in the framing of all four
        assert abs(again - 0.5) < 0.1  # the reset frames it alone
    finally:
        client.close()
        server.stop()
