"""The defaults show the data: a value range fitted to the window per mode, and a default view
from the side of the first steps, on runs like users bring (a plume whose first steps are
faint, a reaction-diffusion front spreading from a corner), measured as the fraction of the
selected steps each picture shows (`chronocl.render.visible_steps`)."""

from __future__ import annotations

import json
import math
import shutil
import warnings

import numpy as np
import pytest

from chronocl import Session, integrate, modes
from chronocl.core.selection import parse_selection
from chronocl.core.tf import DataTF
from chronocl.core.tuning import TUNING
from chronocl.core.values import normalize
from chronocl.data import synthetic
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries, open_series
from chronocl.data.simulations import simulate
from chronocl.integration import fit_range
from chronocl.integration.inmemory import prepare
from chronocl.render import Camera, render
from chronocl.render.default_view import default_camera, series_early_side
from chronocl.render.visible_steps import steps_shown

from .test_cli import assert_one_line_error, cli

SIZE = (96, 96)


@pytest.fixture(scope="module")
def plume() -> TimeSeries:
    return TimeSeries.from_array(simulate("plume", (32, 32, 32), 20))


@pytest.fixture(scope="module")
def front() -> TimeSeries:
    return TimeSeries.from_array(simulate("gray-scott", (24, 24, 24), 16))


def picture(camera: Camera):
    return lambda cv: render(cv, camera, SIZE, jitter=False).array


def test_the_plume_starts_faint(plume):
    peaks = plume.stats.step_max
    assert peaks[0] < 0.15 * max(peaks)  # what the defaults must cope with


def test_fitted_range_is_the_windows_own(plume):
    job = prepare(plume, "0:10")
    lo, hi = job.value_range
    assert plume.vmin <= lo < hi <= max(plume.stats.step_max[:10])
    assert hi < 0.6 * plume.vmax  # the early window is normalised by its own top
    assert prepare(
        plume, "0:10", spec_args={"data_tf": DataTF(value_range="global")}
    ).value_range == (
        plume.vmin,
        plume.vmax,
    )
    assert prepare(
        plume, "0:10", spec_args={"data_tf": DataTF(value_range=(0, 2))}
    ).value_range == (0, 2)


def test_a_store_too_large_for_any_level_is_fitted_from_its_coarsest_level(tmp_path, monkeypatch):
    """Where no stored level is as small as the sample, the coarsest is sampled with a
    stride, never level 0 (a stride through level 0 decodes every chunk of every step)."""
    path = tmp_path / "p.zarr"
    steps = np.stack(list(synthetic.steps("vortex", 12, (128, 96, 112)))).astype(np.float32)
    TimeSeries.from_array(steps, source="p").save(path)  # a stored level: 64x48x56
    series = open_series(path)
    assert series.n_levels >= 2
    coarsest = series.level(series.n_levels - 1)
    monkeypatch.setattr(TUNING, "fit_sample_values", 2000)  # smaller than every level
    assert math.prod(coarsest.volume_shape) > 2000 / 10
    shutil.rmtree(path / "data" / "c")  # level 0's chunks gone: reading one would fail
    selection = parse_selection("0:10", series.n_steps)
    for mode in ("alpha", "max"):
        got = fit_range.window_range(series, selection, modes.get(mode))
        assert got == fit_range.window_range(coarsest, selection, modes.get(mode))
        assert series.vmin <= got[0] < got[1] <= series.vmax


def test_min_is_fitted_to_the_minima(plume):
    hi = prepare(plume, "0:10", "min").value_range[1]
    minima = plume.read(list(range(10))).min(axis=0)
    assert hi <= float(minima.max()) + 1e-9
    assert prepare(plume, "0:10", "max").value_range[1] > hi


def test_min_shows_more_than_at_the_global_range(plume):
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        fitted = integrate(plume, "0:10", "min", engine="numpy")
    assert not [w for w in said if "shows nothing" in str(w.message)]
    at_global = integrate(
        plume, "0:10", "min", engine="numpy", data_tf=DataTF(value_range="global")
    )
    opaque = [int((cv.rgba[..., 3] > 0.05).sum()) for cv in (fitted, at_global)]
    assert opaque[0] > 2 * opaque[1], opaque


@pytest.mark.parametrize("engine", ["numpy", "opencl"])
@pytest.mark.parametrize("mode", ["max", "min"])
def test_t_index_says_when_each_voxel_peaked_at_the_default_range(front, mode, engine):
    """max/min's t_index is the step of the raw extreme on every voxel (issue 48), though the
    window's fitted range clips many voxels to u = 0 or 1, where u ties across the steps."""
    window = "4:14"
    cv = integrate(front, window, mode, engine=engine)
    raw = front.read(list(range(4, 14)))
    pick = np.argmax if mode == "max" else np.argmin
    extreme = pick(raw, axis=0)
    assert np.array_equal(cv.t_index, 4 + extreme)  # numpy's ties: the first step, as ours
    # the old rule, the extreme of the clipped u, differs here: on 44 % of the voxels in max
    # (many clip to u = 1 at several steps), on 0.4 % in min
    u = normalize(raw, *cv.metadata["value_range"])
    assert (pick(u, axis=0) != extreme).mean() > (0.3 if mode == "max" else 0.002)


@pytest.mark.parametrize("mode", ["alpha", "additive", "mean", "first_hit"])
def test_every_step_of_the_faint_plume_shows(plume, mode):
    shown = steps_shown(plume, "0:10:2", mode, picture(Camera(30, 20)), engine="numpy")
    assert shown.fraction == 1.0, shown
    at_global = steps_shown(
        plume,
        "0:10:2",
        mode,
        picture(Camera(30, 20)),
        engine="numpy",
        data_tf=DataTF(value_range="global"),
    )
    assert len(at_global.shown) <= len(shown.shown)


def test_the_default_view_looks_from_the_first_steps(front):
    selection = parse_selection("0:16:3", front.n_steps)
    fitted = prepare(front, "0:16:3").value_range
    base = Camera(30, 25, zoom=1.15)
    camera = series_early_side(front, selection, fitted, base)
    # The seed is in the (0, 0, 0) corner: the camera's eye lies on that side of the box.
    assert all(c < 0 for c in camera.eye_direction())
    for mode in ("alpha", "first_hit", "max", "change"):
        away = steps_shown(front, "0:16:3", mode, picture(base), engine="numpy")
        near = steps_shown(front, "0:16:3", mode, picture(camera), engine="numpy")
        assert near.fraction == 1.0, (mode, near)
        assert near.fraction >= away.fraction


def test_python_and_the_cli_pick_the_same_default_view(front, tmp_path):
    """`chronocl.render(cv)` without a camera looks from the first steps' side as the command
    line does (issue 48), also for a chronovolume saved and loaded; `camera=` overrides."""
    cv = integrate(front, "0:16:3", "first_hit", engine="numpy")
    selection = parse_selection("0:16:3", front.n_steps)
    cli_view = series_early_side(front, selection, cv.metadata["value_range"], Camera())
    assert default_camera(cv) == cli_view != Camera()
    assert all(c < 0 for c in cli_view.eye_direction())  # the seed's corner
    shown = render(cv, size=(64, 64))
    assert shown.array.tobytes() == render(cv, cli_view, size=(64, 64)).array.tobytes()
    assert shown.array.tobytes() != render(cv, Camera(), size=(64, 64)).array.tobytes()
    cv.save(tmp_path / "cv.zarr")
    assert default_camera(Chronovolume.load(tmp_path / "cv.zarr")) == cli_view
    # a run streamed slab by slab into a store keeps them too
    from chronocl.integration.runs.streaming import integrate_to_store

    store = front.save(tmp_path / "front.zarr")
    integrate_to_store(store, "0:16:3", tmp_path / "s.zarr", mode="first_hit", slab=4)
    assert default_camera(Chronovolume.load(tmp_path / "s.zarr")) == cli_view


def test_a_plume_rising_is_seen_from_the_side(plume):
    # Its first steps lie below the last: looking up from below would read upside down.
    base = Camera(30, 20)
    for window in ("0:2", "0:10", "0:20"):
        selection = parse_selection(window, plume.n_steps)
        assert series_early_side(plume, selection, (0.0, 1.0), base) == base


def test_a_session_fits_once_and_slides_at_that_range(plume):
    with Session(plume, engine="numpy", spec=None, mode="alpha") as s:
        s.set_window(0, 6)
        fixed = s.spec.data_tf.value_range
        assert isinstance(fixed, tuple)
        for _ in range(3):
            cv = s.slide(1)
            assert s.spec.data_tf.value_range == fixed
        again = integrate(plume, s.selection.steps, spec=s.spec, engine="numpy")
        np.testing.assert_allclose(cv.rgba, again.rgba, atol=1e-5)
        s.set_spec(mode="min")  # a new mode is fitted again, to the window shown
        assert s.spec.data_tf.value_range == prepare(plume, s.selection, "min").value_range


def test_demo_draws_a_users_series_with_the_steps_each_picture_shows(front, tmp_path):
    store = front.save(tmp_path / "front.zarr").path
    out = tmp_path / "out"
    done = cli("demo", "--data", store, "--window", "0:16:3", "--out", out, "--engine", "numpy")
    assert done.returncode == 0, done.stderr
    report = json.loads((out / "defaults-front.json").read_text())
    assert (out / "defaults-front.png").stat().st_size > 1000
    assert report["window"] == "0:16:3"
    # The default view looks from the seed's corner: the front's history shows.
    for mode in ("alpha", "first_hit", "max", "change", "count"):
        assert report["modes"][mode]["fraction_shown"] == 1.0, (mode, report["modes"][mode])
    assert "first_hit" in done.stderr  # the table of what each picture shows
    bad = cli("demo", "--data", store, "--window", "0:99", "--out", out, "--engine", "numpy")
    assert_one_line_error(bad, "99")


def test_cli_render_looks_from_the_first_steps_unless_told(front, tmp_path):
    store = front.save(tmp_path / "front.zarr").path
    told = tmp_path / "told.png"
    chosen = tmp_path / "chosen.png"
    done = cli("render", store, "-o", chosen, "--window", "0:16:3", "--engine", "numpy")
    assert done.returncode == 0, done.stderr
    done = cli(
        "render",
        store,
        "-o",
        told,
        "--window",
        "0:16:3",
        "--engine",
        "numpy",
        "--azimuth",
        "30",
        "--elevation",
        "20",
    )
    assert done.returncode == 0, done.stderr
    assert chosen.read_bytes() != told.read_bytes()


def test_cli_value_range_normalises_and_max_keeps_its_winners(front, tmp_path):
    """--value-range window|series|LO,HI sets what normalises u and the summary says which;
    max's t_index is the same at every range (issue 48)."""
    store = front.save(tmp_path / "front.zarr").path
    got = {}
    for given, words in [
        ("window", "fitted to the window"),
        ("series", "the series'"),
        ("0.1,0.2", "value range 0.1 to 0.2, given"),
    ]:
        out = tmp_path / f"{given}.zarr"
        flag = ("--value-range", given)
        done = cli("integrate", store, out, "--mode", "max", "--window", "2:12", *flag)
        assert done.returncode == 0, done.stderr
        assert words in " ".join(done.stderr.split()), done.stderr
        got[given] = Chronovolume.load(out)
    assert tuple(got["series"].metadata["value_range"]) == (front.vmin, front.vmax)
    assert tuple(got["0.1,0.2"].metadata["value_range"]) == (0.1, 0.2)
    assert got["window"].metadata["value_range"] != got["series"].metadata["value_range"]
    for cv in got.values():
        assert np.array_equal(cv.t_index, got["window"].t_index)
    assert not np.array_equal(got["0.1,0.2"].rgba, got["window"].rgba)


def test_count_has_its_own_default_tf_and_threshold():
    """count with no TF: its occupancy ramp over the fitted range and threshold 0.25; a TF
    given (here, in a file or a colour map) keeps the plain threshold 0 unless one is given."""
    from chronocl.integration.inmemory import make_spec
    from chronocl.modes import get
    from chronocl.modes.spec import IntegrationSpec

    own = IntegrationSpec(mode="count")
    assert own.data_tf.points == get("count").default_data_points
    assert own.data_tf.value_range == "window" and own.threshold == 0.25
    assert make_spec("count") == own
    assert make_spec("count", threshold=0.1).threshold == pytest.approx(0.1)
    given = DataTF().with_colormap("viridis")
    assert make_spec("count", data_tf=given).threshold == 0.0
    assert IntegrationSpec(mode="count", data_tf=DataTF()).threshold == 0.0
    assert IntegrationSpec(mode="alpha").data_tf == DataTF()  # other modes: the white default
    assert IntegrationSpec.from_dict(own.to_dict()) == own


@pytest.mark.parametrize("series, window", [("plume", "0:10:2"), ("front", "0:16:3")])
def test_every_step_shows_in_counts_default_picture(request, series, window):
    """In the default view, the occupancy ramp tells one step more or less apart where the
    white default's saturated blob did not (there half the steps of the front showed)."""
    data = request.getfixturevalue(series)
    selection = parse_selection(window, data.n_steps)
    camera = series_early_side(data, selection, prepare(data, window).value_range, Camera(30, 25))
    shown = steps_shown(data, window, "count", picture(camera), engine="numpy")
    assert shown.fraction == 1.0, shown
    white = steps_shown(data, window, "count", picture(camera), engine="numpy", data_tf=DataTF())
    assert len(white.shown) <= len(shown.shown)
