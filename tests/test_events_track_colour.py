"""Track colouring (`chronocl.events.colour`, `chronocl.render(colour="track")`, `chronocl
render --colour track`) on hand-made series whose tracks are known by construction: two blobs
that merge (the merged blob takes the colour of the track that goes on through the merge), a
moving blob with no event (one colour), the birth of a second blob (a second colour); each
against a numpy oracle painted from the construction. Then the refusals (a mode without a
winning step, steps the events do not cover, events of other data), each before any step is
read; the time colouring; a render of a merge whose pixels show the two colours and a legend
of both; and the command's one-line refusals.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

import chronocl
from chronocl.core.errors import ChronoclError, InvalidDataError, InvalidParameterError
from chronocl.data.series import TimeSeries, write_series
from chronocl.events.colour import META_KEY, track_colour, track_volumes, winner_modes
from chronocl.events.palette import TRACK_PALETTE, track_rgb

from .bad_input import assert_rejected
from .test_cli import cli

SHAPE = (3, 10, 24)  # Z, Y, X: blobs in the middle z plane
THRESHOLD = 0.5  # what a step shows for the events: value >= 0.5
HALO = 0.2  # a faint value around some blobs: shown by max, under the events' threshold


class Painted:
    """A series of rectangular blobs in the middle z plane, each painted with the track it
    belongs to by construction, so the oracle knows the feature (and track) of every voxel at
    every step. Values rise with the step (0.6 + 0.05 t), so max wins at the last step that
    covers a voxel, first_hit at the first."""

    def __init__(self, steps: int) -> None:
        self.values = np.zeros((steps, *SHAPE), np.float32)
        self.track = np.full((steps, *SHAPE), -1, np.int32)

    def paint(self, t: int, y: tuple[int, int], x: tuple[int, int], track: int, halo=False):
        sl = (t, 1, slice(*y), slice(*x))
        if halo:  # one voxel around it, faint, under the threshold
            around = (t, 1, slice(y[0] - 1, y[1] + 1), slice(x[0] - 1, x[1] + 1))
            self.values[around] = np.maximum(self.values[around], HALO)
        self.values[sl] = 0.6 + 0.05 * t
        self.track[sl] = track

    def series(self) -> TimeSeries:
        return TimeSeries.from_array(self.values)


def oracle(p: Painted, t_index: np.ndarray, steps) -> np.ndarray:
    """The track of every voxel at its winning step, from the painting (-1: none)."""
    out = np.full(t_index.shape, -1, np.int32)
    for s in steps:
        here = t_index == s
        out[here] = p.track[s][here]
    return out


def expected_rgba(cv, tracks: np.ndarray) -> np.ndarray:
    """The track-coloured RGBA: the chronovolume's opacity, each track's palette colour."""
    palette = np.array([track_rgb(k) for k in range(max(1, tracks.max() + 1))], np.float32)
    alpha = cv.rgba[..., 3]
    shown = tracks >= 0
    rgba = np.zeros((*tracks.shape, 4), np.float32)
    rgba[shown, :3] = alpha[shown, None] * palette[tracks[shown]]
    rgba[shown, 3] = alpha[shown]
    return rgba


def merging() -> Painted:
    """A (rows 2..6, 6 wide, track 0) and B (rows 3..5, 4 wide, track 1) move towards each
    other and merge at step 3; the merged blob goes on to step 4. A is larger, so the merged
    feature overlaps A's more (higher Jaccard) and continues A's track."""
    p = Painted(5)
    p.paint(0, (2, 7), (1, 7), 0, halo=True)
    p.paint(0, (3, 6), (17, 21), 1)
    p.paint(1, (2, 7), (3, 9), 0, halo=True)
    p.paint(1, (3, 6), (15, 19), 1)
    p.paint(2, (2, 7), (5, 11), 0, halo=True)
    p.paint(2, (3, 6), (13, 17), 1)
    p.paint(3, (2, 7), (7, 16), 0)  # overlaps both: the merge
    p.paint(4, (2, 7), (8, 17), 0)
    return p


# -- by construction ---------------------------------------------------------------------------
@pytest.mark.parametrize("mode", ["max", "first_hit"])
def test_a_merge_shows_two_colours_flowing_into_one(mode):
    """Before the merge each blob's voxels have their own track's colour; the merged blob's
    voxels have the colour of the track the graph continues through it (A's: track 0); B's
    track ends at the merge. Equal to the oracle voxel for voxel; the halo is transparent."""
    p = merging()
    s = p.series()
    g = chronocl.events(s, threshold=THRESHOLD)
    assert [(e["kind"], e["step"]) for e in g.events if e["kind"] != "continuation"] == [
        ("merge", 2)
    ]
    merged = next(f for f in g.features if f["step"] == 3)
    assert merged["track"] == 0  # the larger blob's track goes on
    assert [(t["id"], t["start"], t["end"]) for t in g.tracks] == [(0, 0, 4), (1, 0, 2)]
    cv = chronocl.integrate(s, "0:5", mode=mode)
    got = track_colour(cv, g, series=s)
    want = oracle(p, cv.t_index, range(5))
    (tracks,) = track_volumes([cv.t_index], g, s)
    np.testing.assert_array_equal(tracks, want)
    np.testing.assert_array_equal(got.rgba, expected_rgba(cv, want))
    np.testing.assert_array_equal(got.t_index, cv.t_index)
    # exactly two colours: A's (through the merge) and B's (up to it)
    lit = got.rgba[got.rgba[..., 3] > 0]
    assert len({tuple(np.round(v, 5)) for v in lit[:, :3] / lit[:, 3:]}) == 2
    # the merged blob's own voxels (step 4's) take A's colour under max, which wins there
    if mode == "max":
        assert (tracks[1, 2:7, 8:17] == 0).all()
    # B's start, never covered by the merged blob, keeps B's colour
    assert (tracks[1, 3:6, 18:21] == 1).all()
    # the faint halo shows in the chronovolume but belongs to no feature: transparent
    halo = (p.values.max(axis=0) == HALO) & (cv.rgba[..., 3] > 0)
    assert halo.any() and (got.rgba[halo] == 0).all()
    meta = got.metadata[META_KEY]
    assert meta["by"] == "id" and [t["id"] for t in meta["tracks"]] == [0, 1]
    alpha = cv.rgba[..., 3].astype(np.float64)
    lost = alpha[want < 0].sum() / alpha.sum()
    assert meta["untracked_opacity"] == pytest.approx(lost, rel=1e-6)
    assert 0 < lost < 0.5  # the halo: shown by the mode, in no feature
    assert meta["tracks"][0]["rgb"] == pytest.approx([c / 255 for c in TRACK_PALETTE[0]])


def test_a_moving_blob_with_no_event_is_one_colour():
    p = Painted(4)
    for t in range(4):
        p.paint(t, (3, 7), (2 + 3 * t, 7 + 3 * t), 0)
    s = p.series()
    g = chronocl.events(s, threshold=THRESHOLD)
    assert {e["kind"] for e in g.events} == {"continuation"} and len(g.tracks) == 1
    cv = chronocl.integrate(s, "0:4", mode="max")
    got = track_colour(cv, g, series=s)
    want = oracle(p, cv.t_index, range(4))
    assert set(np.unique(want)) == {-1, 0}
    np.testing.assert_array_equal(got.rgba, expected_rgba(cv, want))
    shown = got.rgba[..., 3] > 0
    assert shown.sum() == (p.track.max(axis=0) == 0).sum()  # every voxel the blob swept
    assert [t["id"] for t in got.metadata[META_KEY]["tracks"]] == [0]


def test_a_birth_brings_a_second_colour():
    """A blob that is there from step 0 (track 0) and one born at step 2 (track 1): the
    newborn's voxels are the second track's colour, the first's stay the first's."""
    p = Painted(4)
    for t in range(4):
        p.paint(t, (1, 4), (2 + t, 6 + t), 0)
    p.paint(2, (6, 9), (14, 18), 1)
    p.paint(3, (6, 9), (15, 19), 1)
    s = p.series()
    g = chronocl.events(s, threshold=THRESHOLD)
    assert [(e["kind"], e["next_step"]) for e in g.events if e["kind"] != "continuation"] == [
        ("birth", 2)
    ]
    assert [(t["id"], t["start"]) for t in g.tracks] == [(0, 0), (1, 2)]
    for mode in ("max", "first_hit", "min", "change"):
        cv = chronocl.integrate(s, "0:4", mode=mode)
        got = track_colour(cv, g, series=s)
        want = oracle(p, cv.t_index, range(4))
        np.testing.assert_array_equal(got.rgba, expected_rgba(cv, want))
    cv = chronocl.integrate(s, "0:4", mode="max")
    got = track_colour(cv, g, series=s)
    newborn = got.rgba[1, 6:9, 15:19]
    rgb = newborn[..., :3] / newborn[..., 3:]
    np.testing.assert_allclose(rgb, np.broadcast_to(track_rgb(1), rgb.shape), atol=1e-6)


def test_min_shows_only_voxels_a_feature_held_throughout():
    """min's winning step is the voxel's lowest: a voxel left by the blob has its minimum
    outside every feature (transparent), one the blob covered at every step keeps its
    track."""
    p = Painted(3)
    for t in range(3):
        p.paint(t, (2, 6), (4 + t, 10 + t), 0)
    s = p.series()
    g = chronocl.events(s, threshold=THRESHOLD)
    cv = chronocl.integrate(s, "0:3", mode="min")
    got = track_colour(cv, g, series=s)
    always = (p.track == 0).all(axis=0)
    assert always.sum() == 4 * 4  # columns 6..9
    assert ((got.rgba[..., 3] > 0) == (always & (cv.rgba[..., 3] > 0))).all()


def test_coloured_by_time_a_track_takes_the_time_colour_where_it_first_shows():
    p = Painted(4)
    for t in range(4):
        p.paint(t, (1, 4), (2 + t, 6 + t), 0)
    p.paint(2, (6, 9), (14, 18), 1)
    p.paint(3, (6, 9), (15, 19), 1)
    s = p.series()
    g = chronocl.events(s, threshold=THRESHOLD)
    cv = chronocl.integrate(s, "0:4", mode="max")
    got = track_colour(cv, g, series=s, by="time")
    spec = cv.spec
    positions = spec.time_tf.positions_of(cv.steps, 4)
    rgb, _ = spec.time_tf.evaluate(positions)
    first = {0: 0, 1: 2}  # track -> the step where it first shows
    want = oracle(p, cv.t_index, range(4))
    alpha = cv.rgba[..., 3]
    expected = np.zeros_like(got.rgba)
    for k, step in first.items():
        here = want == k
        expected[here, :3] = alpha[here, None] * rgb[step].astype(np.float32)
        expected[here, 3] = alpha[here]
    np.testing.assert_allclose(got.rgba, expected, atol=1e-6)
    assert got.metadata[META_KEY]["by"] == "time"
    # over a window that starts at step 1, track 0 first shows at its first step
    later = chronocl.integrate(s, "1:4", mode="max")
    recoloured = track_colour(later, g, series=s, by="time")
    t0 = next(t for t in recoloured.metadata[META_KEY]["tracks"] if t["id"] == 0)
    assert t0["first_step"] == 1
    r, _ = later.spec.time_tf.evaluate(later.spec.time_tf.positions_of(later.steps, 4))
    assert t0["rgb"] == pytest.approx(np.clip(r[0], 0, 1).tolist(), abs=1e-6)


# -- refusals, before any step is read -----------------------------------------------------
@pytest.mark.parametrize("mode", ["alpha", "additive", "mean", "count"])
def test_modes_without_a_winning_step_are_refused_naming_those_with_one(mode):
    p = merging()
    s = p.series()
    g = chronocl.events(s, threshold=THRESHOLD)
    cv = chronocl.integrate(s, "0:5", mode=mode)
    assert winner_modes() == ("first_hit", "max", "min", "change")
    with pytest.raises(ChronoclError, match=rf"first_hit, max, min, change; {mode} blends"):
        _read_nothing(lambda: track_colour(cv, g, series=s))
    with pytest.raises(InvalidParameterError, match=f"{mode} blends"):
        _read_nothing(lambda: chronocl.render(cv, colour="track", events=g))


def _read_nothing(call):
    """`call()` with every read of a step failing the test."""
    before = TimeSeries.read_brick

    def refuse(*args, **kwargs):
        raise AssertionError("a step was read before the checks")

    TimeSeries.read_brick = refuse
    try:
        return call()
    finally:
        TimeSeries.read_brick = before


def test_what_cannot_be_coloured_is_refused_before_any_read():
    p = merging()
    s = p.series()
    g = chronocl.events(s, "0:3", threshold=THRESHOLD)
    cv = chronocl.integrate(s, "0:5", mode="max")
    with pytest.raises(InvalidParameterError, match="step 3, 4 has none"):
        _read_nothing(lambda: track_colour(cv, g, series=s))
    with pytest.raises(InvalidParameterError, match="by 'colour'"):
        _read_nothing(lambda: track_colour(cv, g, series=s, by="colour"))
    with pytest.raises(InvalidParameterError, match=r"events=chronocl\.events"):
        _read_nothing(lambda: chronocl.render(cv, colour="track"))
    with pytest.raises(InvalidParameterError, match=r"markers=graph\.markers"):
        _read_nothing(lambda: chronocl.render(cv, events=g))
    with pytest.raises(InvalidParameterError, match="not one of tf"):
        _read_nothing(lambda: chronocl.render(cv, colour="tracks", events=g))
    small = chronocl.integrate(TimeSeries.from_array(p.values[:, :, :5, :5]), "0:3", mode="max")
    with pytest.raises(InvalidParameterError, match="24x10x3 volume"):
        _read_nothing(lambda: track_colour(small, g, series=s))
    # an array's chronovolume names no store: the series must be given
    whole = chronocl.events(s, threshold=THRESHOLD)
    with pytest.raises(InvalidParameterError, match="give series="):
        track_colour(cv, whole)


def test_events_of_other_data_are_refused():
    p = merging()
    g = chronocl.events(p.series(), threshold=THRESHOLD)
    other = p.values.copy()
    other[:, 1, 8, :] = 0.9  # a new feature in every step
    s = TimeSeries.from_array(other)
    cv = chronocl.integrate(s, "0:5", mode="max")
    with pytest.raises(InvalidDataError, match="found in other data"):
        track_colour(cv, g, series=s)


# -- pictures ----------------------------------------------------------------------------------
def _chroma(rgb: np.ndarray) -> np.ndarray:
    """Colours scaled to their largest channel: the hue and saturation, whatever the shade."""
    rgb = rgb.astype(np.float64)
    return rgb / np.maximum(rgb.max(axis=-1, keepdims=True), 1e-9)


def _near(pixels: np.ndarray, colour, tol=0.06) -> np.ndarray:
    bright = pixels.max(axis=-1) > 60
    close = np.abs(_chroma(pixels) - _chroma(np.array(colour))).max(axis=-1) < tol
    return bright & close


@pytest.fixture(scope="module")
def merge_store(tmp_path_factory):
    """The merge, thickened through z so the picture is opaque, as a store."""
    path = tmp_path_factory.mktemp("tracks") / "merge.zarr"
    values = merging().values
    thick = np.repeat(values[:, 1:2], 8, axis=1)
    thick[:, [0, -1]] = 0
    write_series(path, iter(thick), n_steps=5, volume_shape=thick.shape[1:], dtype="float32")
    return path


def test_a_render_of_a_merge_shows_the_two_colours_and_their_legend(merge_store, tmp_path):
    """Looking down z at the merge: A's colour on the left and through the merged blob, B's on
    the right, nothing else coloured; the legend under it has a swatch of each."""
    from chronocl.render import Camera

    g = chronocl.events(merge_store, threshold=THRESHOLD)
    cv = chronocl.integrate(chronocl.open(merge_store), "0:5", mode="max")
    camera = Camera(0.0, 0.0, 1.0, projection="orthographic", frame="box")
    image = chronocl.render(cv, camera, (480, 240), colour="track", events=g, legend=True)
    path = image.save(tmp_path / "merge.png")
    with Image.open(path) as im:
        pixels = np.asarray(im.convert("RGB"))
    picture = pixels[:240]
    a, b = _near(picture, TRACK_PALETTE[0]), _near(picture, TRACK_PALETTE[1])
    assert a.sum() > 500 and b.sum() > 100
    xs_a, xs_b = np.nonzero(a)[1], np.nonzero(b)[1]
    assert np.median(xs_a) < np.median(xs_b)  # A came from the left, B from the right
    assert xs_b.min() > 240  # B's colour only right of the middle, where B came from
    # no third colour: the only others blend the two where they meet (trilinear sampling)
    other = np.nonzero((picture.max(axis=-1) > 60) & ~a & ~b)[1]
    assert np.abs(other - xs_b.min()).max() <= 10
    legend = pixels[240:]
    for colour in TRACK_PALETTE[:2]:
        assert (legend == colour).all(axis=-1).sum() >= 16  # a swatch of each
    # the same picture from a chronovolume coloured first
    coloured = track_colour(cv, g)
    again = chronocl.render(coloured, camera, (480, 240), legend=True)
    np.testing.assert_array_equal(np.asarray(again.array), np.asarray(image.array))


def test_cli_render_colours_by_track(merge_store, tmp_path):
    events = tmp_path / "events.json"
    assert cli("events", merge_store, "--threshold", "0.5", "-o", events).returncode == 0
    out = tmp_path / "tracks.png"
    view = ["--azimuth", "0", "--elevation", "0", "--projection", "orthographic"]
    base = ["render", merge_store, "--mode", "max", "--size", "320x200", *view]
    result = cli(*base, "-o", out, "--events", events, "--colour", "track")
    assert result.returncode == 0, result.stderr
    saved = tmp_path / "saved.zarr"
    both = cli(
        *base,
        "--mode",
        "first_hit",
        "-o",
        tmp_path / "two.png",
        "--events",
        events,
        "--colour",
        "track",
        "--save-chronovolume",
        saved,
    )
    assert both.returncode == 0, both.stderr
    with Image.open(out) as im:
        pixels = np.asarray(im.convert("RGB"))
    for colour in TRACK_PALETTE[:2]:
        assert _near(pixels[:200], colour).sum() > 50
        assert (pixels == colour).all(axis=-1).sum() >= 16  # its legend swatch
    assert _near(pixels[:200], TRACK_PALETTE[2]).sum() == 0  # no third track
    for mode in ("max", "first_hit"):
        cv = chronocl.Chronovolume.load(tmp_path / f"saved-{mode}.zarr")
        assert cv.metadata[META_KEY]["by"] == "id"
        assert [t["id"] for t in cv.metadata[META_KEY]["tracks"]] == [0, 1]


def test_cli_track_colour_refusals(merge_store, tmp_path):
    events = tmp_path / "events.json"
    assert (
        cli(
            "events",
            merge_store,
            "--window",
            "0:3",
            "--threshold",
            "0.5",
            "-o",
            events,
            "--no-picture",
        ).returncode
        == 0
    )
    out = tmp_path / "x.png"
    base = ["render", merge_store, "-o", out, "--size", "64x64"]
    session = tmp_path / "session.json"
    session.write_text(json.dumps({}))
    for args, needle in (
        (["--mode", "max", "--colour", "track"], "--colour track colours by the tracks"),
        (["--mode", "alpha", "--events", events, "--colour", "track"], "alpha blends"),
        (
            ["--mode", "max,additive", "--events", events, "--colour", "track-time"],
            "additive blends",
        ),
        (["--mode", "max", "--events", events, "--colour", "rainbow"], "not one of tf"),
        (
            ["--mode", "max", "--window", "0:5", "--events", events, "--colour", "track"],
            "step 3, 4 has none",
        ),
        (
            ["--mode", "max", "--events", events, "--colour", "track", "--level", "1"],
            "leave out --level",
        ),
        (
            ["--mode", "max", "--events", events, "--colour", "track", "--variables", "a"],
            "leave out --variables",
        ),
    ):
        assert_rejected([*base, *args], needle, [merge_store, events], [out], tmp_path)
    assert_rejected(
        ["render", "--state", session, "-o", out, "--colour", "track"],
        "--colour does not combine with --state",
        [merge_store, events],
        [out],
    )


def test_first_hit_with_the_events_tf_and_threshold_colours_every_voxel_it_shows():
    """Events found with a TF's opacity > 0.1 (its value range given) and first_hit over the
    same TF with threshold 0.1: each voxel's first hit lies in a feature, so every voxel
    first_hit shows has a track."""
    from chronocl.core.tf import DataTF

    p = merging()
    p.values[0, 1, 3:6, 15:17] = 0.05  # a faint edge ahead of B, which covers it at step 1
    s = p.series()
    tf = DataTF(points=((0.0, 1, 1, 1, 0.0), (1.0, 1, 1, 1, 1.0)), value_range=(0.0, 1.0))
    g = chronocl.events(s, tf=tf, opacity=0.1)
    cv = chronocl.integrate(s, "0:5", mode="first_hit", data_tf=tf, threshold=0.1)
    got = track_colour(cv, g, series=s)
    shown = cv.rgba[..., 3] > 0
    assert shown.sum() > 100  # the halo (0.2) shows too: opacity 0.2 > 0.1
    np.testing.assert_array_equal(got.rgba[..., 3], cv.rgba[..., 3])
    assert (cv.t_index[1, 3:6, 15:17] == 1).all()
    # at threshold 0 the faint edge is the first hit there, in no feature: transparent
    edge = chronocl.integrate(s, "0:5", mode="first_hit", data_tf=tf)
    assert (edge.t_index[1, 3:6, 15:17] == 0).all() and (edge.rgba[1, 3:6, 15:17, 3] > 0).all()
    assert (track_colour(edge, g, series=s).rgba[1, 3:6, 15:17] == 0).all()


def test_the_render_and_the_events_picture_share_the_track_colours():
    from matplotlib import colormaps

    palette = [*colormaps["tab10"].colors, *colormaps["tab20"].colors[1::2]]
    for k in range(45):
        assert track_rgb(k) == pytest.approx(palette[k % 20], abs=1e-9)


def test_a_legend_of_more_tracks_than_fit_keeps_the_largest():
    from PIL import ImageDraw

    from chronocl.render.legends import track_swatches
    from chronocl.render.panels import label_font

    tracks = [{"id": k, "rgb": list(track_rgb(k)), "voxels": 10 + k} for k in range(40)]
    image = Image.new("RGB", (220, 30))
    drawn = track_swatches(
        ImageDraw.Draw(image), tracks, (0, 0, 220, 24), label_font(12), (255,) * 3
    )
    assert 0 < len(drawn) < 40
    assert drawn == sorted(drawn) and min(drawn) == 40 - len(drawn)  # the largest, by id
    pixels = np.asarray(image)
    for k in drawn:
        assert (pixels == TRACK_PALETTE[k % 20]).all(axis=-1).any()
    wide = Image.new("RGB", (2000, 30))
    assert track_swatches(
        ImageDraw.Draw(wide), tracks, (0, 0, 2000, 24), label_font(12), (255,) * 3
    ) == list(range(40))


def test_the_legend_knows_a_track_coloured_chronovolume_by_its_metadata_key():
    from chronocl.render.legends import TRACK_KEY

    assert TRACK_KEY == META_KEY


def test_the_command_notes_a_panel_that_lost_much_of_its_opacity(capsys):
    from chronocl.cli.render import note_untracked

    def cv(mode, share):
        return chronocl.Chronovolume(
            np.zeros((1, 1, 1, 4), np.float32),
            metadata={"spec": {"mode": mode}, META_KEY: {"untracked_opacity": share}},
        )

    note_untracked([cv("max", 0.1), cv("first_hit", 0.61)])
    lines = capsys.readouterr().err
    assert "first_hit: 61% of its opacity" in lines and "max" not in lines


# -- data without a store: series= ------------------------------------------------------------
def _thick_merge() -> np.ndarray:
    """The merge thickened through z, as `merge_store` holds it."""
    thick = np.repeat(merging().values[:, 1:2], 8, axis=1)
    thick[:, [0, -1]] = 0
    return thick


def test_an_in_memory_series_is_coloured_by_track_with_series(merge_store):
    """An array's chronovolume and events name no store: with series= the render colours by
    track, the same picture as the store's; render_views too, over two modes."""
    from chronocl.render import Camera

    values = _thick_merge()
    s = TimeSeries.from_array(values)
    g = chronocl.events(s, threshold=THRESHOLD)
    cv = chronocl.integrate(s, "0:5", mode="max")
    assert cv.metadata.get("store") is None and g.meta.get("store") is None
    camera = Camera(0.0, 0.0, 1.0, projection="orthographic", frame="box")
    image = chronocl.render(cv, camera, (480, 240), colour="track", events=g, series=s, legend=True)
    pixels = np.asarray(image.array)[..., :3]
    for colour in TRACK_PALETTE[:2]:
        assert _near(pixels[:240], colour).sum() > 100
        assert (pixels[240:] == colour).all(axis=-1).sum() >= 16  # its legend swatch
    stored = chronocl.integrate(chronocl.open(merge_store), "0:5", mode="max")
    g_stored = chronocl.events(merge_store, threshold=THRESHOLD)
    same = chronocl.render(stored, camera, (480, 240), colour="track", events=g_stored, legend=True)
    np.testing.assert_array_equal(np.asarray(image.array), np.asarray(same.array))
    # the same series as an array (T, Z, Y, X); and parallel views of two modes
    first = chronocl.integrate(s, "0:5", mode="first_hit")
    views = chronocl.render_views(
        [cv, first], camera, (160, 80), colour="track", events=g, series=values
    )
    assert views.array.shape[1] >= 320
    lit = np.asarray(views.array)[..., :3]
    assert _near(lit, TRACK_PALETTE[0]).sum() > 50 and _near(lit, TRACK_PALETTE[1]).sum() > 20


def _no_work(monkeypatch):
    """Every read of a step, every re-integration along the camera and every draw fail the
    test: a refusal must come before any of them."""
    from chronocl.render import views

    def refuse(*args, **kwargs):
        raise AssertionError("work started before the checks")

    monkeypatch.setattr(TimeSeries, "read_brick", refuse)
    monkeypatch.setattr(views, "following", refuse)
    monkeypatch.setattr(views, "raycaster", refuse)
    monkeypatch.setattr(views, "default_camera", refuse)


def test_without_series_data_with_no_store_is_refused_in_one_line_before_any_work(monkeypatch):
    s = merging().series()
    g = chronocl.events(s, threshold=THRESHOLD)
    cv = chronocl.integrate(s, "0:5", mode="max")
    _no_work(monkeypatch)
    for call in (
        lambda: chronocl.render(cv, colour="track", events=g),
        lambda: chronocl.render_views([cv, cv], colour="track-time", events=g),
        lambda: track_colour(cv, g),
    ):
        with pytest.raises(ChronoclError, match=r"give series=") as caught:
            call()
        assert "\n" not in str(caught.value)
        assert "name a store" in str(caught.value)
    # series= of other data, of another kind, or without colour="track": refused as early
    for series, needle in (
        (np.zeros((5, 3, 10, 20), np.float32), "20x10x3 volumes, the chronovolume is 24x10x3"),
        (np.zeros((3, *SHAPE), np.float32), "has 3 steps"),
        (np.zeros(SHAPE, np.float32), r"must be \(T, Z, Y, X\)"),
        (42, "not int"),
    ):
        with pytest.raises(InvalidParameterError, match=needle) as caught:
            chronocl.render(cv, colour="track", events=g, series=series)
        assert "\n" not in str(caught.value)
    with pytest.raises(InvalidParameterError, match="give it with colour='track'"):
        chronocl.render(cv, series=s)


# -- the legend of many tracks ----------------------------------------------------------------
class _Measured:
    """An ImageDraw that counts (and, `cached`, remembers) its label measurements."""

    def __init__(self, draw, cached: bool = False) -> None:
        self.draw, self.cached, self.measured, self.known = draw, cached, 0, {}

    def textlength(self, text, font=None):
        if self.cached and text in self.known:
            return self.known[text]
        self.measured += 1
        self.known[text] = self.draw.textlength(text, font=font)
        return self.known[text]

    def __getattr__(self, name):
        return getattr(self.draw, name)


def _reference_swatches(draw, tracks, box, font, text_rgb) -> list[int]:
    """The legend as first written: every count of tracks from all of them down laid out in
    full until one fits (quadratic; here with its measurements remembered)."""
    x0, y0, width, height = box
    title = "tracks" if tracks else "no tracks"
    draw.text((x0, y0 + 1), title, fill=text_rgb, font=font)
    top, bottom = font.getbbox("Ag")[1::2]
    line = int(bottom - top) + 6
    side = max(6, line - 6)
    start = x0 + int(draw.textlength("tracks", font=font)) + 10
    lines = max(1, (height + 4) // line)

    def widths(ids):
        return [side + 4 + draw.textlength(str(k), font=font) + 10 for k in ids]

    def fits(ids, more):
        tail = draw.textlength(f"+{more} more", font=font) if more else 0
        used, row = 0.0, 0
        for w in [*widths(ids), tail]:
            if used and start + used + w > x0 + width:
                row, used = row + 1, 0.0
            used += w
        return row < lines

    by_size = sorted(tracks, key=lambda t: (-t.get("voxels", 0), t["id"]))
    n = len(by_size)
    while n > 0 and not fits(sorted(t["id"] for t in by_size[:n]), len(tracks) - n):
        n -= 1
    shown = sorted(by_size[:n], key=lambda t: t["id"])
    x, y = start, y0
    for t in shown:
        label = str(t["id"])
        w = side + 4 + draw.textlength(label, font=font) + 10
        if x > start and x + w > x0 + width:
            x, y = start, y + line
        colour = tuple(round(min(max(c, 0.0), 1.0) * 255) for c in t["rgb"])
        draw.rectangle((x, y + 2, x + side, y + 2 + side), fill=colour, outline=text_rgb)
        draw.text((x + side + 4, y + 1), label, fill=text_rgb, font=font)
        x += w
    if n < len(tracks):
        more = f"+{len(tracks) - n} more"
        if x > start and x + draw.textlength(more, font=font) > x0 + width:
            x, y = start, y + line
        draw.text((x, y + 1), more, fill=text_rgb, font=font)
    return [t["id"] for t in shown]


def _many_tracks(n: int, seed: int = 0) -> list[dict]:
    """`n` tracks, ids with gaps (1 to 4 digits), sizes with ties, in no order."""
    rng = np.random.default_rng(seed)
    ids = np.sort(rng.choice(max(3 * n, 10), n, replace=False))
    voxels = rng.integers(1, max(2, n // 3), n)
    tracks = [
        {"id": int(k), "rgb": list(track_rgb(int(k))), "voxels": int(v)}
        for k, v in zip(ids, voxels, strict=True)
    ]
    rng.shuffle(tracks)
    return tracks


def _both(tracks, box, size=(0, 0)):
    """The legend drawn by `track_swatches` and by the reference: ids, pixels, measurements."""
    from PIL import ImageDraw

    from chronocl.render.legends import track_swatches
    from chronocl.render.panels import label_font

    font = label_font(12)
    w, h = size if size != (0, 0) else (box[0] + box[2] + 20, box[1] + box[3] + 20)
    got, want = Image.new("RGB", (w, h)), Image.new("RGB", (w, h))
    counted = _Measured(ImageDraw.Draw(got))
    ids = track_swatches(counted, tracks, box, font, (255,) * 3)
    ref = _reference_swatches(
        _Measured(ImageDraw.Draw(want), cached=True), tracks, box, font, (255,) * 3
    )
    return ids, ref, np.asarray(got), np.asarray(want), counted.measured


@pytest.mark.parametrize("n", [0, 1, 9, 10, 11, 40, 99, 100, 101, 150])
def test_the_legend_lays_out_as_the_straightforward_search_does(n):
    """For track counts about the digits' edges ("+9 more", "+10 more") and boxes from one
    line a swatch wide to many lines: the same tracks, the same pixels, as the reference."""
    tracks = _many_tracks(n, seed=n)
    boxes = [(0, 0, 220, 24), (0, 0, 2000, 24), (0, 0, 90, 60), (0, 0, 30, 24), (5, 3, 300, 80)]
    boxes += [(0, 0, w, 40) for w in range(60, 700, 37)]
    for box in boxes:
        ids, ref, got, want, _ = _both(tracks, box)
        assert ids == ref, box
        np.testing.assert_array_equal(got, want, err_msg=str(box))


def test_a_legend_of_2000_tracks_measures_each_label_once():
    """2000 tracks: as the reference in boxes where all or most fit (the reference's search is
    short there); and in a small box, where the first search laid out every count from 2000
    down (17 s a panel), the labels are measured once each: O(n) measurements, not one per
    track per count tried."""
    tracks = _many_tracks(2000, seed=7)
    counts = []
    for box in ((0, 0, 1800, 1400), (0, 0, 1800, 1080), (0, 0, 1800, 1000)):
        ids, ref, got, want, measured = _both(tracks, box)
        assert ids == ref, box
        np.testing.assert_array_equal(got, want)
        assert measured <= 2000 + 40
        counts.append(len(ids))
    assert counts[0] == 2000 and 1500 < counts[2] < counts[1] < 2000  # all; "+34 more"; ...
    from PIL import ImageDraw

    from chronocl.render.legends import track_swatches
    from chronocl.render.panels import label_font

    for n in (250, 500, 1000, 2000):
        counted = _Measured(ImageDraw.Draw(Image.new("RGB", (240, 40))))
        ids = track_swatches(
            counted, _many_tracks(n, n), (0, 0, 220, 24), label_font(12), (255,) * 3
        )
        assert 0 < len(ids) < 20
        # each distinct label once, the title, and a "+N more" per count tried (log n)
        assert counted.measured <= n + 2 + 4 * int(np.log2(n) + 1), (n, counted.measured)
