"""`chronocl render` and the demo gallery end to end; bad render options exit 2 with one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

import chronocl
from chronocl import modes
from chronocl.demo import FIGURES, run_demo

from .test_cli import assert_one_line_error, cli


@pytest.fixture(scope="module")
def vortex(tmp_path_factory):
    path = tmp_path_factory.mktemp("render") / "v.zarr"
    assert cli("generate", "vortex", path, "--shape", "24x24x24", "--steps", "6").returncode == 0
    return path


def test_parallel_views_turntable_and_saved_chronovolumes(tmp_path, vortex):
    from PIL import Image as PILImage

    result = cli(
        "render",
        vortex,
        "-o",
        tmp_path / "views.png",
        "--mode",
        "alpha,max",
        "--mode",
        "additive",
        "--window",
        "0:6:2",
        "--size",
        "64x48",
        "--clip",
        "0,0,-1,0.2",
        "--outline",
        "--background",
        "#202020",
        "--turntable",
        tmp_path / "turn.gif",
        "--frames",
        "4",
        "--save-chronovolume",
        tmp_path / "cv.zarr",
    )
    assert result.returncode == 0, result.stderr
    image = PILImage.open(tmp_path / "views.png")
    assert image.width == 3 * 64 and image.height > 48  # three panels, legend below
    pixels = np.asarray(image.convert("RGB"))[:48]
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20  # something was drawn
    import imageio.v3 as iio

    frames = iio.imread(tmp_path / "turn.gif", index=None)
    assert frames.shape[0] == 4
    assert not np.array_equal(frames[0], frames[1])  # the camera moved
    for mode in ("alpha", "max", "additive"):
        cv = chronocl.Chronovolume.load(tmp_path / f"cv-{mode}.zarr")
        assert cv.spec.mode == mode and cv.steps == (0, 2, 4)


def test_mp4_turntable_with_odd_sizes(tmp_path, vortex):
    import imageio.v3 as iio

    # a declared dependency (test_suite_rules fails where it is missing); without it the
    # turntable is refused in one line (test_a_movie_without_imageio_ffmpeg_is_one_line)
    pytest.importorskip("imageio_ffmpeg")
    result = cli(
        "render",
        vortex,
        "-o",
        tmp_path / "t.png",
        "--size",
        "33x31",
        "--turntable",
        tmp_path / "t.mp4",
        "--frames",
        "3",
    )
    assert result.returncode == 0, result.stderr
    frames = iio.imread(tmp_path / "t.mp4", index=None)
    assert frames.shape[0] == 3 and frames.shape[1] % 2 == 0 and frames.shape[2] % 2 == 0


@pytest.mark.parametrize("install", ["missing", "broken"])
def test_a_movie_without_imageio_ffmpeg_is_one_line(tmp_path, vortex, monkeypatch, install):
    """No imageio-ffmpeg (or one that finds no ffmpeg): one line naming the install, exit 2,
    before any work (no picture written), not imageio's fallback on another plugin."""
    import contextlib
    import io
    import sys
    import warnings

    from chronocl.cli.app import main

    if install == "missing":
        monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # import raises ImportError
    else:
        ffmpeg = pytest.importorskip("imageio_ffmpeg")

        def no_exe():
            raise RuntimeError("No ffmpeg exe could be found. Install ffmpeg on your system.")

        monkeypatch.setattr(ffmpeg, "get_ffmpeg_exe", no_exe)
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)  # main() sets it
    args = ["render", vortex, "-o", tmp_path / "t.png", "--turntable", tmp_path / "t.mp4"]
    monkeypatch.setattr(sys, "argv", ["chronocl", *map(str, args)])
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit) as exit_:
        main()
    assert exit_.value.code == 2
    lines = [line for line in stderr.getvalue().splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("chronocl: error:"), lines
    assert "imageio-ffmpeg" in lines[0] and "pip install imageio-ffmpeg" in lines[0], lines[0]
    assert list(tmp_path.iterdir()) == []


def test_silhouette_follows_the_camera(tmp_path, vortex):
    result = cli(
        "render",
        vortex,
        "-o",
        tmp_path / "s.png",
        "--enhance",
        "silhouette",
        "--window",
        "0:6:3",
        "--size",
        "48x48",
        "--azimuth",
        "90",
        "--save-chronovolume",
        tmp_path / "s.zarr",
    )
    assert result.returncode == 0, result.stderr
    view = chronocl.Chronovolume.load(tmp_path / "s.zarr").spec.enhance.view
    np.testing.assert_allclose(
        view, [-np.cos(np.radians(20)), -np.sin(np.radians(20)), 0], atol=1e-9
    )


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--size", "8x8"], "outside 16..8192"),
        (["--size", "9000x100"], "outside 16..8192"),
        (["--size", "big"], "WxH"),
        (["--azimuth", "nan"], "azimuth"),
        (["--time-tf", "rainbow"], "unknown time TF preset"),
        (["--mode", "sum"], "unknown mode"),
        (["--clip", "1,2"], "clip"),
        (["--projection", "fisheye"], "fisheye"),
        (["--background", "no-such-colour"], "unknown colour"),
        (["--turntable", "{tmp}/t.txt"], "video suffix"),
        (["--clip", "1,0,0,5"], "clip offset is 5"),
        (["--clip", "0,0,0,0"], "normal is (0, 0, 0)"),
        (["--zoom", "0"], "camera zoom"),
        (["--frames", "1", "--turntable", "{tmp}/t.gif"], "use 2 to 3600"),
        (["--engine", "cuda"], "unknown engine"),
        (["--enhance", "glow"], "unknown enhancement"),
        (["--normalize", "sum"], "unknown additive normalisation"),
        (["--window", "0:99"], "outside the series"),
        (["--save-chronovolume", "{tmp}/cv.png"], "cannot tell the chronovolume format"),
    ],
)
def test_bad_render_options(tmp_path, vortex, args, needle):
    argv = [a.format(tmp=tmp_path) for a in args]
    result = cli("render", vortex, "-o", tmp_path / "o.png", *argv)
    assert_one_line_error(result, needle)
    assert not (tmp_path / "o.png").exists()
    assert not [p for p in tmp_path.iterdir() if ".partial-" in p.name]


def test_demo_writes_the_gallery(tmp_path):
    paths = run_demo(tmp_path, shape_xyz=(24, 24, 24), n_steps=30, size=64, run_shape=(20, 20, 20))
    *figures, defaults = paths
    assert len(figures) == len(FIGURES) and all(p.exists() for p in paths)
    assert (tmp_path / "gallery.png").exists()
    page = (tmp_path / "index.html").read_text()
    assert all(p.name in page for p in figures) and "white where all steps" in page
    # Every mode's default picture of the reaction-diffusion run, with what it shows.
    report = json.loads(defaults.with_suffix(".json").read_text())
    assert set(report["modes"]) == set(modes.names())
    for shown in report["modes"].values():
        assert 0 <= shown["fraction_shown"] <= 1
        assert len(shown["shown"]) + len(shown["hidden"]) == 8  # window 0:24:3


@pytest.mark.parametrize("suffix", [".mp4", ".webm", ".mkv", ".gif"])
def test_every_video_suffix_holds_every_frame_at_its_size(tmp_path, suffix):
    """Each format written holds the frames given, at their size padded even (a WebM asked
    for H.264 was once an empty file, and WebM/MKV frames were resized to 16-pixel blocks)."""
    import imageio.v3 as iio

    from chronocl.render.video import write_video

    if suffix != ".gif":
        pytest.importorskip("imageio_ffmpeg")
    frames = [np.full((31, 33, 3), 40 * i, np.uint8) for i in range(5)]
    path = write_video(frames, tmp_path / f"m{suffix}", fps=10)
    plugin = "pillow" if suffix == ".gif" else "FFMPEG"
    read = list(iio.imiter(path, plugin=plugin))
    assert len(read) == 5
    assert read[0].shape[:2] == ((31, 33) if suffix == ".gif" else (32, 34))
    assert [int(f[..., :3].mean()) for f in read] == pytest.approx(
        [40 * i for i in range(5)], abs=3
    )
