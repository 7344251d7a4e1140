"""Events through time (`chronocl.events`, `chronocl events`) on series whose events are known
by construction: blobs that merge, split, are born, die, leave through a face, move without
an event; periodic faces joining a blob (checked against connected-components-3d's own
periodic labelling and against a brute-force graph of the voxels for every connectivity);
6 against 26 connectivity on a diagonal contact; a value threshold against a TF opacity
threshold; global tracks bridging a step of weak overlap that local matching breaks; the JSON
round trip; and the command: a store written by chronocl, its JSON and picture, and every
refusal one line, exit 2, nothing written.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import sys
import tempfile
import threading
import time
import tomllib
from importlib.metadata import version
from pathlib import Path

import cc3d
import networkx as nx
import numpy as np
import pytest
from packaging.requirements import Requirement
from PIL import Image

import chronocl
from chronocl.core.errors import (
    InvalidParameterError,
    InvalidSelectionError,
    InvalidTransferFunctionError,
    StoreCorruptError,
    UnknownNameError,
)
from chronocl.core.selection import Selection
from chronocl.core.tf import DataTF, TFSetting, lut_lerp32
from chronocl.core.values import normalize
from chronocl.data.series import TimeSeries, open_series, write_series
from chronocl.events import EventGraph, load_events
from chronocl.events import processes as events_processes
from chronocl.events import run as events_run
from chronocl.events.extra import MissingExtraError
from chronocl.events.features import Mask, label, label_step, offsets, parse_periodic
from chronocl.events.tracking import overlaps

from .bad_input import assert_rejected
from .test_cli import cli

SHAPE = (3, 8, 16)  # Z, Y, X: blobs lie in the middle z plane, away from the z faces


def series(steps: int, shape=SHAPE) -> np.ndarray:
    return np.zeros((steps, *shape), np.float32)


def paint(a: np.ndarray, t: int, y: tuple[int, int], x: tuple[int, int], value=1.0) -> None:
    """A blob at step t: the middle z plane, rows y0:y1, columns x0:x1."""
    a[t, 1, y[0] : y[1], x[0] : x[1]] = value


def kinds(graph: EventGraph) -> list[tuple]:
    """(kind, step, sources, targets) of every event, in the graph's order."""
    return [(e["kind"], e["step"], e["sources"], e["targets"]) for e in graph.events]


def track_lists(graph: EventGraph) -> list[list[tuple[int, int]]]:
    return [[tuple(n) for n in t["features"]] for t in graph.tracks]


# -- events known by construction --------------------------------------------------------------
def test_two_blobs_merge():
    a = series(4)
    paint(a, 0, (2, 5), (1, 4))
    paint(a, 0, (2, 5), (10, 13))
    paint(a, 1, (2, 5), (3, 6))
    paint(a, 1, (2, 5), (8, 11))
    paint(a, 2, (2, 5), (4, 11))  # overlaps both
    paint(a, 3, (2, 5), (5, 12))
    g = chronocl.events(a, threshold=0.5)
    assert kinds(g) == [
        ("continuation", 0, [1], [1]),
        ("continuation", 0, [2], [2]),
        ("merge", 1, [1, 2], [1]),
        ("continuation", 2, [1], [1]),
    ]
    assert [len([f for f in g.features if f["step"] == s]) for s in range(4)] == [2, 2, 1, 1]
    # one of the two tracks goes on through the merge, the other ends at it
    ends = sorted((t["start"], t["end"]) for t in g.tracks)
    assert ends == [(0, 1), (0, 3)]
    assert g.counts() == {"continuation": 3, "merge": 1}


def test_a_blob_splits():
    a = series(3)
    paint(a, 0, (2, 5), (4, 12))
    paint(a, 1, (2, 5), (4, 12))
    paint(a, 2, (2, 5), (3, 7))
    paint(a, 2, (2, 5), (9, 13))
    g = chronocl.events(a, threshold=0.5, tracks="local")
    assert kinds(g) == [("continuation", 0, [1], [1]), ("split", 1, [1], [1, 2])]
    assert len(g.tracks) == 2 and g.meta["tracks_method"] == "local"


def test_birth_and_death():
    a = series(4)
    paint(a, 1, (2, 4), (2, 5))  # step 0 is empty: born at 1
    paint(a, 2, (2, 4), (2, 5))
    paint(a, 2, (5, 7), (9, 12))  # a second one, born at 2
    paint(a, 3, (5, 7), (9, 12))  # the first dies at 3
    g = chronocl.events(a, threshold=0.5)
    assert kinds(g) == [
        ("birth", 0, [], [1]),
        ("continuation", 1, [1], [1]),
        ("birth", 1, [], [2]),
        ("death", 2, [1], []),
        ("continuation", 2, [2], [1]),
    ]
    assert not any(e["at_boundary"] for e in g.events)
    assert track_lists(g) == [[(1, 1), (2, 1)], [(2, 2), (3, 1)]]


def test_a_moving_blob_is_one_continuation_and_one_track_by_both_methods():
    a = series(6)
    for t in range(6):
        paint(a, t, (2, 5), (1 + t, 5 + t))
    for method in ("global", "local"):
        g = chronocl.events(a, threshold=0.5, tracks=method)
        assert {e["kind"] for e in g.events} == {"continuation"} and len(g.events) == 5
        assert track_lists(g) == [[(t, 1) for t in range(6)]]
        xs = [f["centroid_zyx"][2] for f in g.features]
        np.testing.assert_allclose(xs, [2.5 + t for t in range(6)])


def test_a_blob_leaving_through_a_face_is_an_exit_and_one_coming_in_an_entry():
    a = series(4)
    paint(a, 0, (2, 5), (10, 14))
    paint(a, 1, (2, 5), (12, 16))  # touches the x face
    paint(a, 2, (2, 5), (0, 3))  # gone on the right; a new one comes in on the left
    paint(a, 3, (2, 5), (1, 4))
    g = chronocl.events(a, threshold=0.5)
    assert kinds(g) == [
        ("continuation", 0, [1], [1]),
        ("exit", 1, [1], []),
        ("entry", 1, [], [1]),
        ("continuation", 2, [1], [1]),
    ]
    exit_, entry = g.events[1], g.events[2]
    assert exit_["at_boundary"] and entry["at_boundary"]
    assert [f["touches_boundary"] for f in g.features] == [False, True, True, False]
    # with x periodic there is no face to leave through: a death and a birth (the two
    # positions share no voxel)
    wrapped = chronocl.events(a, threshold=0.5, periodic="x")
    went = [e["kind"] for e in wrapped.events]
    assert went == ["continuation", "death", "birth", "continuation"]
    assert not any(f["touches_boundary"] for f in wrapped.features)


def test_a_death_in_the_middle_is_no_exit():
    a = series(2)
    paint(a, 0, (3, 5), (6, 9))
    g = chronocl.events(a, threshold=0.5)
    assert kinds(g) == [("death", 0, [1], [])] and not g.events[0]["at_boundary"]


# -- periodic boundaries -----------------------------------------------------------------------
def test_periodic_faces_join_a_blob_and_measure_it_unwrapped():
    a = series(1)
    paint(a, 0, (2, 4), (0, 2), value=2.0)
    paint(a, 0, (2, 4), (14, 16), value=2.0)
    apart = chronocl.events(a, threshold=1.0).features
    assert [f["size"] for f in apart] == [4, 4]
    assert all(f["touches_boundary"] for f in apart)
    (joined,) = chronocl.events(a, threshold=1.0, periodic="x").features
    assert joined["size"] == 8 and joined["value_sum"] == 16.0
    assert joined["wraps"] == "x" and not joined["touches_boundary"]
    # x indices 14, 15, 16, 17 unwrapped: the centre 15.5, the box through the face
    assert joined["centroid_zyx"] == [1.0, 2.5, 15.5]
    assert joined["bbox_zyx"] == [[1, 2], [2, 4], [14, 18]]
    # another axis periodic does not join them
    assert len(chronocl.events(a, threshold=1.0, periodic="yz").features) == 2


def test_a_ring_around_a_periodic_axis_has_the_whole_axis_as_its_box():
    a = series(1)
    paint(a, 0, (3, 4), (0, 16))
    (ring,) = chronocl.events(a, threshold=0.5, periodic="x").features
    assert ring["wraps"] == "x" and ring["bbox_zyx"][2] == [0, 16]
    assert 0.0 <= ring["centroid_zyx"][2] < 16.0


def test_periodic_corner_contact_needs_26_connectivity():
    """Two voxels in opposite corners of the y-x square touch across both faces at once."""
    shown = np.zeros((3, 4, 5), bool)
    shown[1, 0, 0] = shown[1, 3, 4] = True
    for connectivity, n in ((6, 2), (18, 1), (26, 1)):
        labels, _ = label(shown, connectivity, (False, True, True))
        assert labels.max() == n, connectivity
    labels, wraps = label(shown, 26, (False, True, False))  # x does not wrap: apart
    assert labels.max() == 2 and wraps == {}


def _reference_labels(shown: np.ndarray, connectivity: int, periodic) -> np.ndarray:
    """Components by brute force: a graph of every shown voxel and each of its neighbours
    (`connectivity`, wrapping on the periodic axes), numbered by their first voxel."""
    most = {6: 1, 18: 2, 26: 3}[connectivity]
    steps = [d for d in itertools.product((-1, 0, 1), repeat=3) if 0 < sum(map(abs, d)) <= most]
    g = nx.Graph()
    voxels = [tuple(int(c) for c in v) for v in np.argwhere(shown)]
    g.add_nodes_from(voxels)
    for v in voxels:
        for d in steps:
            w = []
            for axis, (c, s, n) in enumerate(zip(v, d, shown.shape, strict=True)):
                c += s
                if not 0 <= c < n:
                    if not periodic[axis]:
                        break
                    c %= n
                w.append(c)
            else:
                if shown[tuple(w)]:
                    g.add_edge(v, tuple(w))
    out = np.zeros(shown.shape, np.uint32)
    for k, comp in enumerate(sorted(nx.connected_components(g), key=min), 1):
        for v in comp:
            out[v] = k
    return out


@pytest.mark.parametrize("seed", range(6))
def test_periodic_labels_equal_a_brute_force_graph(seed):
    rng = np.random.default_rng(seed)
    shape = tuple(int(n) for n in rng.integers(1, 6, size=3))
    shown = rng.random(shape) < 0.3
    for connectivity in (6, 18, 26):
        for periodic in itertools.product((False, True), repeat=3):
            labels, _ = label(shown, connectivity, periodic)
            want = _reference_labels(shown, connectivity, periodic)
            np.testing.assert_array_equal(labels, want, err_msg=f"{connectivity} {periodic}")


@pytest.mark.parametrize("seed", range(4))
def test_periodic_6_connectivity_equals_cc3d_own_periodic_labelling(seed):
    rng = np.random.default_rng(100 + seed)
    shown = rng.random((6, 7, 8)) < 0.35
    labels, _ = label(shown, 6, (True, True, True))
    theirs = cc3d.connected_components(shown, connectivity=6, periodic_boundary=True)
    pairs = np.unique(np.stack([labels.ravel(), theirs.ravel()]), axis=1)
    assert pairs.shape[1] == len(np.unique(labels)) == len(np.unique(theirs))  # one-to-one


def test_half_the_neighbour_offsets():
    assert [len(offsets(c)) for c in (6, 18, 26)] == [3, 9, 13]


# -- connectivity, masks -----------------------------------------------------------------------
def test_6_and_26_connectivity_on_a_diagonal_contact():
    """Two blobs meeting at one corner are one feature at 26 connectivity, two at 6 and 18;
    through time the 26-connected pair merges, the 6-connected one does not."""
    a = np.zeros((2, 6, 6, 6), np.float32)
    a[0, 1:3, 1:3, 1:3] = 1
    a[1, 1:3, 1:3, 1:3] = 1
    a[1, 3:5, 3:5, 3:5] = 1  # corner to corner with the first
    a[0, 3:5, 3:5, 3:5] = 0
    counts = {
        c: len(chronocl.events(a[1:], threshold=0.5, connectivity=c).features) for c in (6, 18, 26)
    }
    assert counts == {6: 2, 18: 2, 26: 1}
    assert [e["kind"] for e in chronocl.events(a, threshold=0.5, connectivity=6).events] == [
        "continuation",
        "birth",
    ]
    assert [e["kind"] for e in chronocl.events(a, threshold=0.5, connectivity=26).events] == [
        "continuation"
    ]


def _two_levels() -> np.ndarray:
    a = series(1)
    paint(a, 0, (2, 4), (2, 5), value=0.2)
    paint(a, 0, (2, 4), (10, 13), value=0.8)
    a[0, 0, 0, 0] = 1.0  # the range's top
    return a


def test_a_value_threshold_and_a_tf_opacity_threshold_show_different_voxels():
    a = _two_levels()
    by_value = chronocl.events(a, threshold=0.5).features
    assert [(f["size"], f["bbox_zyx"][2]) for f in by_value] == [(1, [0, 1]), (6, [10, 13])]
    # a hat TF over [0, 1]: opaque around 0.2, clear from 0.5 up
    hat = DataTF(
        points=((0, 1, 1, 1, 0), (0.2, 1, 1, 1, 1), (0.5, 1, 1, 1, 0), (1, 1, 1, 1, 0)),
        value_range=(0.0, 1.0),
    )
    g = chronocl.events(a, tf=hat, opacity=0.5)
    assert [(f["size"], f["bbox_zyx"][2]) for f in g.features] == [(6, [2, 5])]
    assert g.meta["mask"]["kind"] == "opacity" and g.meta["mask"]["value_range"] == [0.0, 1.0]
    # the mask is the engines' own lookup of opacity at the normalised value
    u = normalize(a[0], 0.0, 1.0)
    want = lut_lerp32(hat.lut, u)[..., 3] > np.float32(0.5)
    np.testing.assert_array_equal(Mask.of_tf(hat, (0.0, 1.0), 0.5)(a[0]), want)
    # a TFSetting and a TF file give the same
    assert chronocl.events(a, tf=TFSetting(data_tf=hat), opacity=0.5).features == g.features


def test_a_tf_without_a_range_is_fitted_to_the_window_as_integrate_fits_it(tmp_path):
    from chronocl import modes
    from chronocl.integration.fit_range import window_range

    rng = np.random.default_rng(3)
    a = rng.random((3, *SHAPE)).astype(np.float32)
    s = TimeSeries.from_array(a)
    g = chronocl.events(s, "0:2", tf=DataTF(), opacity=0.3)
    want = window_range(s, Selection((0, 1), 3), modes.get(modes.DEFAULT))
    assert g.meta["mask"]["value_range"] == list(want)
    TFSetting(data_tf=DataTF()).save(tmp_path / "tf.json")
    assert chronocl.events(s, "0:2", tf=tmp_path / "tf.json", opacity=0.3).features == g.features


def test_non_finite_values_are_never_shown():
    """A series refuses NaN, but a step read from elsewhere may hold one: the masks skip it."""
    a = series(1)[0]
    a[1, 2:4, 2:5] = 1.0
    a[1, 3, 3] = a[1, 6, 6] = np.nan
    for mask in (Mask.of_threshold(0.5), Mask.of_tf(DataTF(), (0.0, 1.0), 0.0)):
        (f,) = label_step(a, mask).features
        assert f.size == 5 and f.value_sum == 5.0


def test_world_coordinates_follow_the_spacing():
    a = series(1)
    paint(a, 0, (2, 4), (4, 8), value=3.0)
    s = TimeSeries.from_array(a, spacing=(0.5, 2.0, 4.0))  # dx, dy, dz
    (f,) = chronocl.events(s, threshold=1.0).features
    assert f["centroid_zyx"] == [1.0, 2.5, 5.5]
    assert f["world_xyz"] == [2.75, 5.0, 4.0]
    assert f["value_sum"] == 24.0 and f["size"] == 8


def test_label_step_numbers_features_by_their_first_voxel():
    shown = np.zeros((2, 4, 4), np.float32)
    shown[1, 0, 3] = 1  # first in raster order (z slowest)
    shown[0, 3, 0] = 1
    step = label_step(shown, Mask.of_threshold(0.5), step=7)
    assert [(f.step, f.id, f.centroid_zyx) for f in step.features] == [
        (7, 1, (0.0, 3.0, 0.0)),
        (7, 2, (1.0, 0.0, 3.0)),
    ]
    assert step.labels[0, 3, 0] == 1 and step.labels[1, 0, 3] == 2


def test_overlaps_count_shared_voxels():
    a = np.array([[[1, 1, 0, 2, 2]]], np.uint32)
    b = np.array([[[0, 3, 3, 3, 0]]], np.uint32)
    assert overlaps(a, b) == {(1, 3): 1, (2, 3): 1}


def test_large_steps_are_masked_measured_and_matched_in_chunks_alike(monkeypatch):
    """A large step is masked, measured and matched a few million voxels at a time; with tiny
    chunks the features are cc3d's own statistics and the overlaps a count over the whole
    arrays, whether the shown voxels' indices are given or found."""
    from chronocl.events import features as features_module
    from chronocl.events import tracking as tracking_module

    rng = np.random.default_rng(11)
    a = (rng.random((2, 9, 10, 11)) * 2.0).astype(np.float32)  # 15 % shown at 1.7: specks
    whole = [label_step(step, Mask.of_threshold(1.7), t) for t, step in enumerate(a)]
    monkeypatch.setattr(features_module, "CHUNK", 97)
    monkeypatch.setattr(tracking_module, "CHUNK", 89)
    chunked = [label_step(step, Mask.of_threshold(1.7), t) for t, step in enumerate(a)]
    for w, c, step in zip(whole, chunked, a, strict=True):
        np.testing.assert_array_equal(w.labels, c.labels)
        scratch = np.ones(step.shape, bool)  # a mask written into a buffer used before
        shown = Mask.of_threshold(1.7)(step, scratch)
        assert shown is scratch
        np.testing.assert_array_equal(shown, (step >= 1.7))
        again = label_step(step, Mask.of_threshold(1.7), w.step, scratch=scratch)
        np.testing.assert_array_equal(again.labels, w.labels)
        np.testing.assert_array_equal(c.voxels, np.flatnonzero(c.labels))
        stats = cc3d.statistics(c.labels)
        assert [f.size for f in c.features] == stats["voxel_counts"][1:].tolist()
        for f, centroid, box in zip(
            c.features, stats["centroids"][1:], stats["bounding_boxes"][1:], strict=True
        ):
            np.testing.assert_allclose(f.centroid_zyx, centroid, rtol=1e-12)
            assert f.bbox_zyx == tuple((b.start, b.stop) for b in box)
            assert f.value_sum == pytest.approx(float(step[c.labels == f.id].sum(dtype=np.float64)))
        assert [f.size for f in w.features] == [f.size for f in c.features]
    first, second = chunked
    both = (first.labels > 0) & (second.labels > 0)
    pairs, counts = np.unique(
        np.stack([first.labels[both], second.labels[both]]), axis=1, return_counts=True
    )
    want = {(int(x), int(y)): int(n) for (x, y), n in zip(pairs.T, counts, strict=True)}
    assert len(want) > 1
    assert overlaps(first.labels, second.labels) == want
    assert overlaps(first.labels, second.labels, first.voxels) == want


def test_the_memory_budget_bounds_the_steps_in_flight(monkeypatch):
    """Within a budget of one step's working set, one step is read and labelled at a time;
    the timings of the run are filled in."""
    a = series(6)
    for t in range(6):
        paint(a, t, (2, 5), (1 + t % 4, 5 + t % 4))
    s = TimeSeries.from_array(a)
    per_step = a[0].size * (a.dtype.itemsize + 13)
    assert events_run.steps_in_flight(s, per_step) == 1
    assert events_run.steps_in_flight(s, 100 * per_step) == events_run.AHEAD
    read, lock, held, most = [], threading.Lock(), [0], [0]
    plain = TimeSeries.read_brick
    original_label = events_run.label_step

    def counted(self, steps, *args, **kwargs):
        with lock:
            read.extend(steps)
            held[0] += 1
            most[0] = max(most[0], held[0])
        return plain(self, steps, *args, **kwargs)

    def labelled(*args, **kwargs):
        try:
            return original_label(*args, **kwargs)
        finally:
            with lock:
                held[0] -= 1

    monkeypatch.setattr(TimeSeries, "read_brick", counted)
    monkeypatch.setattr(events_run, "label_step", labelled)
    spent = events_run.Timings()
    job = events_run.prepare(s, threshold=0.5)
    g = events_run.find(job, timings=spent, memory=per_step)
    assert sorted(read) == list(range(6)) and most[0] == 1
    assert [e["kind"] for e in g.events] == ["continuation"] * 5
    parts = (spent.read_s, spent.label_s, spent.match_s, spent.wait_s, spent.tracks_s)
    assert spent.total_s > 0 and all(p >= 0 for p in parts) and spent.label_s > 0


# -- tracks: global against local --------------------------------------------------------------
def _weak_step() -> np.ndarray:
    """A blob A moving right; at step 2 a rival S overlaps A's step 1 more than A's own next
    position does (similarities 0.46 against 0.2), and dies at step 3 while A goes on."""
    a = series(5)
    paint(a, 0, (1, 5), (2, 8))
    paint(a, 1, (1, 5), (4, 10))
    paint(a, 2, (1, 3), (3, 10))  # S: 12 of A1's voxels, 14 in all
    paint(a, 2, (4, 6), (4, 10))  # A2: 6 of A1's voxels (row 4)
    paint(a, 3, (4, 6), (5, 11))
    paint(a, 4, (4, 6), (6, 12))
    return a


def test_global_tracks_bridge_a_weak_overlap_that_local_matching_breaks():
    a = _weak_step()
    local = chronocl.events(a, threshold=0.5, tracks="local")
    global_ = chronocl.events(a, threshold=0.5, tracks="global")
    # the same events either way: A1 splits into S (id 1) and A2 (id 2); S dies
    assert (
        kinds(local)
        == kinds(global_)
        == [
            ("continuation", 0, [1], [1]),
            ("split", 1, [1], [1, 2]),
            ("death", 2, [1], []),
            ("continuation", 2, [2], [1]),
            ("continuation", 3, [1], [1]),
        ]
    )
    sim = {(tuple(e["source"]), tuple(e["target"])): e["similarity"] for e in local.edges}
    assert sim[(1, 1), (2, 1)] == pytest.approx(12 / 26)
    assert sim[(1, 1), (2, 2)] == pytest.approx(6 / 30)
    # local follows the rival at the split and loses A; global keeps A whole
    assert track_lists(local) == [[(0, 1), (1, 1), (2, 1)], [(2, 2), (3, 1), (4, 1)]]
    assert track_lists(global_) == [[(0, 1), (1, 1), (2, 2), (3, 1), (4, 1)], [(2, 1)]]
    by_track = {f["track"] for f in global_.features if f["step"] != 2 or f["id"] == 2}
    assert by_track == {0}


# -- the API's inputs --------------------------------------------------------------------------
def test_windows_stores_and_arrays(tmp_path):
    a = series(6)
    for t in range(6):
        paint(a, t, (2, 5), (1 + t, 5 + t))
    path = tmp_path / "s.zarr"
    write_series(path, iter(a), n_steps=6, volume_shape=SHAPE, dtype="float32")
    from_path = chronocl.events(path, "0:6:2", threshold=0.5)
    assert from_path.meta["steps"] == [0, 2, 4]
    assert [(e["source"][0], e["target"][0]) for e in from_path.edges] == [(0, 2), (2, 4)]
    opened = open_series(path)
    for window in (slice(0, 6, 2), [0, 2, 4], Selection((0, 2, 4), 6), "0:6:2"):
        assert chronocl.events(opened, window, threshold=0.5).features == from_path.features
    assert chronocl.events(a, "0:6:2", threshold=0.5).features == from_path.features
    assert from_path.meta["store"] == str(path.resolve())
    with pytest.raises(InvalidSelectionError, match="ambiguous"):
        chronocl.events(a, (0, 3), threshold=0.5)  # as every chronocl window: say 0:3 or [0, 3]


def test_steps_are_read_once_each_through_the_series_and_a_few_at_a_time(monkeypatch):
    a = series(12)
    for t in range(12):
        paint(a, t, (2, 5), (1 + t % 4, 5 + t % 4))
    s = TimeSeries.from_array(a)
    read, lock, held, most = [], threading.Lock(), [0], [0]
    plain = TimeSeries.read_brick

    def counted(self, steps, *args, **kwargs):
        with lock:
            read.extend(steps)
            held[0] += 1
            most[0] = max(most[0], held[0])
        return plain(self, steps, *args, **kwargs)

    original_label = events_run.label_step

    def labelled(*args, **kwargs):
        try:
            return original_label(*args, **kwargs)
        finally:
            with lock:
                held[0] -= 1

    monkeypatch.setattr(TimeSeries, "read_brick", counted)
    monkeypatch.setattr(events_run, "label_step", labelled)
    g = chronocl.events(s, threshold=0.5)
    assert sorted(read) == list(range(12)) and len(g.features) == 12
    assert most[0] <= events_run.AHEAD


def _stored_vortex(path: Path, steps: int = 6) -> np.ndarray:
    from chronocl.data import synthetic

    shape = (20, 24, 28)
    a = np.stack([np.ascontiguousarray(s) for s in synthetic.steps("vortex", steps, shape, 0)])
    write_series(path, iter(a), n_steps=steps, volume_shape=shape, dtype="float32")
    return a


def _label_folders() -> set[str]:
    shared = events_processes.SHARED_MEMORY
    folder = shared if shared.is_dir() else Path(tempfile.gettempdir())
    return {p.name for p in folder.glob("chronocl-events-*")}


@pytest.mark.parametrize(
    "kwargs",
    [
        {"threshold": 0.3},
        {"threshold": 0.3, "periodic": "xz", "connectivity": 6},
        {"tf": DataTF(), "opacity": 0.3},
    ],
)
def test_a_stored_series_labels_on_worker_processes_as_on_threads(tmp_path, monkeypatch, kwargs):
    """From a store, with two cores, the steps are labelled on two worker processes that read
    them themselves: the same graph as the threads find from the same steps in memory, and no
    label file is left behind."""
    a = _stored_vortex(tmp_path / "v.zarr")
    before = _label_folders()
    monkeypatch.setenv("CHRONOCL_THREADS", "2")
    monkeypatch.setattr(events_run, "PROCESS_MIN_VOXELS", 0)
    spent = events_run.Timings()
    job = events_run.prepare(open_series(tmp_path / "v.zarr"), **kwargs)
    stored = events_run.find(job, timings=spent)
    assert spent.processes == 2 and spent.worker_peak_rss > 0
    in_memory = chronocl.events(a, **kwargs)  # an array: threads
    assert len(stored.features) > 6 and stored.events
    for part in ("features", "edges", "events", "tracks"):
        assert getattr(stored, part) == getattr(in_memory, part)
    assert _label_folders() == before


def test_a_worker_process_s_error_reaches_the_caller_as_itself(tmp_path, monkeypatch):
    _stored_vortex(tmp_path / "v.zarr")
    chunk = next((tmp_path / "v.zarr").rglob("c/3/*/*/*"))
    chunk.write_bytes(b"not a chunk")
    monkeypatch.setenv("CHRONOCL_THREADS", "2")
    monkeypatch.setattr(events_run, "PROCESS_MIN_VOXELS", 0)
    before = _label_folders()
    with pytest.raises(StoreCorruptError, match=r"\(step 3\)"):
        chronocl.events(tmp_path / "v.zarr", threshold=0.3)
    assert _label_folders() == before


def test_small_steps_and_one_core_label_on_threads(tmp_path, monkeypatch):
    _stored_vortex(tmp_path / "v.zarr", 3)
    job = events_run.prepare(open_series(tmp_path / "v.zarr"), threshold=0.3)
    monkeypatch.setenv("CHRONOCL_THREADS", "2")
    spent = events_run.Timings()
    events_run.find(job, timings=spent)  # 20 x 24 x 28 voxels: below PROCESS_MIN_VOXELS
    assert spent.processes == 0
    monkeypatch.setattr(events_run, "PROCESS_MIN_VOXELS", 0)
    monkeypatch.setenv("CHRONOCL_THREADS", "1")
    events_run.find(job, timings=spent)
    assert spent.processes == 0


@pytest.mark.parametrize(
    ("kwargs", "error", "needle"),
    [
        ({}, InvalidParameterError, "threshold="),
        ({"threshold": 0.5, "tf": DataTF()}, InvalidParameterError, "not both"),
        ({"threshold": 0.5, "opacity": 0.2}, InvalidParameterError, "give tf="),
        ({"tf": DataTF(), "opacity": -0.1}, InvalidParameterError, "outside [0, 1)"),
        ({"tf": DataTF(), "opacity": 1.0}, InvalidParameterError, "outside [0, 1)"),
        ({"threshold": float("nan")}, InvalidParameterError, "not finite"),
        ({"threshold": "high"}, InvalidParameterError, "not a number"),
        ({"threshold": 0.5, "connectivity": 8}, InvalidParameterError, "6 (faces)"),
        ({"threshold": 0.5, "periodic": "xw"}, InvalidParameterError, "periodic"),
        ({"threshold": 0.5, "tracks": "best"}, UnknownNameError, "global"),
        ({"tf": 3}, InvalidTransferFunctionError, "not a transfer function"),
    ],
)
def test_bad_arguments_are_one_line_each(kwargs, error, needle):
    with pytest.raises(error) as info:
        chronocl.events(series(2), **kwargs)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_the_events_extra_is_installed_within_its_range():
    """As tests/test_suite_rules.py checks the runtime and dev dependencies: in CI's run on
    the lower bounds (CHRONOCL_LOWEST=1) each library of the extra is at its lower bound."""
    pyproject = Path(__file__).parent.parent / "pyproject.toml"
    extra = tomllib.loads(pyproject.read_text())["project"]["optional-dependencies"]["events"]
    lowest = os.environ.get("CHRONOCL_LOWEST") == "1"
    for text in extra:
        req = Requirement(text)
        have = version(req.name)
        assert have in req.specifier, f"{req.name} {have} is outside {req.specifier}"
        floor = next(s.version for s in req.specifier if s.operator == ">=")
        assert not lowest or have == floor, f"{req.name} {have} is not its lower bound {floor}"


def test_a_missing_extra_names_the_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "cc3d", None)
    with pytest.raises(MissingExtraError, match=r"pip install 'chronocl\[events\]'"):
        chronocl.events(series(2), threshold=0.5)


# -- the graph and its JSON --------------------------------------------------------------------
def test_json_round_trip_graph_and_frames(tmp_path):
    a = _weak_step()
    g = chronocl.events(a, threshold=0.5)
    path = g.save(tmp_path / "e.json")
    back = load_events(path)
    assert back == g and EventGraph.load(path) == g
    assert json.loads(g.to_json())["format"] == "chronocl-events"
    graph = back.graph
    assert isinstance(graph, nx.DiGraph)
    assert graph.number_of_nodes() == len(g.features) and graph.number_of_edges() == len(g.edges)
    assert graph.nodes[2, 2]["track"] == 0 and graph.nodes[2, 2]["size"] == 12
    assert graph.edges[(1, 1), (2, 2)]["overlap"] == 6
    assert nx.is_directed_acyclic_graph(graph)
    assert graph.graph["tracks_method"] == "global"
    frames = g.to_pandas()
    assert list(frames) == ["features", "edges", "events", "tracks"]
    assert len(frames["features"]) == len(g.features) and "centroid_zyx" in frames["features"]
    with pytest.raises(FileExistsError):
        g.save(path)  # no overwrite unless asked
    g.save(path, overwrite=True)
    (tmp_path / "bad.json").write_text('{"format": "other"}')
    with pytest.raises(chronocl.ChronoclError, match="not a chronocl events file"):
        load_events(tmp_path / "bad.json")


def test_the_picture_is_drawn(tmp_path):
    g = chronocl.events(_weak_step(), threshold=0.5)
    g.save_picture(tmp_path / "g.png")
    image = np.asarray(Image.open(tmp_path / "g.png").convert("L"))
    assert image.shape[0] >= 400 and image.shape[1] >= 600 and image.std() > 10
    labels = [t.get_text() for t in g.figure().axes[0].texts]
    assert "split" in labels and "death" in labels and "T0" in labels


# -- the command -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def store(tmp_path_factory):
    path = tmp_path_factory.mktemp("events") / "in" / "s.zarr"
    a = _weak_step()
    times = [0.5 * t for t in range(len(a))]
    write_series(path, iter(a), n_steps=len(a), volume_shape=SHAPE, dtype="float32", times=times)
    return path


def test_cli_writes_json_and_picture(store, tmp_path):
    out = tmp_path / "events.json"
    result = cli("events", store, "--window", "0:5", "--threshold", "0.5", "-o", out)
    assert result.returncode == 0, result.stderr
    assert "wrote" in result.stderr and "1 split" in result.stderr
    written = load_events(out)
    assert written == chronocl.events(store, "0:5", threshold=0.5)
    assert written.meta["times"] == [0.0, 0.5, 1.0, 1.5, 2.0]
    with Image.open(tmp_path / "events.png") as im:
        assert im.format == "PNG" and im.width >= 600 and im.height >= 400
    local = tmp_path / "local.json"
    args = ["--threshold", "0.5", "-o", local, "--tracks", "local", "--picture", tmp_path / "p.png"]
    assert cli("events", store, *args, "--connectivity", "6").returncode == 0
    assert load_events(local).meta["tracks_method"] == "local"
    assert (tmp_path / "p.png").exists() and not (tmp_path / "local.png").exists()


def test_cli_help_has_examples():
    from typer.testing import CliRunner

    from chronocl.cli import app

    text = CliRunner().invoke(app, ["events", "--help"]).output
    assert "Examples" in text and "chronocl events vortex.zarr" in text


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["{missing}", "--threshold", "0.5"], "does not exist"),
        (["{store}", "--threshold", "0.5", "--window", "4:2"], "reversed"),
        (["{store}", "--tf", "{tf}", "--opacity", "-0.5"], "outside [0, 1)"),
        (["{store}", "--threshold", "0.5", "--connectivity", "8"], "connectivity 8"),
        (["{store}", "--threshold", "0.5", "--periodic", "w"], "periodic"),
        (["{store}", "--threshold", "0.5", "--tracks", "nearest"], "unknown track method"),
        (["{store}"], "say what a step shows"),
        (["{store}", "--threshold", "0.5", "--tf", "{tf}"], "not both"),
    ],
)
def test_cli_refuses_bad_input_in_one_line(store, tmp_path, args, needle):
    tf = tmp_path / "tf.json"
    TFSetting(data_tf=DataTF(value_range=(0.0, 1.0))).save(tf)
    out = tmp_path / "out.json"
    filled = [
        a.format(store=store, missing=tmp_path / "nope.zarr", tf=tf) if "{" in a else a
        for a in args
    ]
    assert_rejected(
        ["events", *filled, "-o", out],
        needle,
        inputs=[store, tf],
        outputs=[out, tmp_path / "out.png"],
        folder=tmp_path,
    )


def test_cli_refuses_bad_outputs(store, tmp_path):
    missing = tmp_path / "no-such-folder" / "e.json"
    common = ["events", store, "--threshold", "0.5"]
    assert_rejected([*common, "-o", missing], "does not exist", [store], [missing])
    assert not missing.parent.exists()
    assert_rejected([*common, "-o", tmp_path / "e.txt"], "must end in .json", [store])
    assert_rejected(
        [*common, "-o", tmp_path / "e.json", "--picture", tmp_path / "e.jpg"],
        "must end in .png",
        [store],
        [tmp_path / "e.json"],
    )
    (tmp_path / "e.json").write_text("{}")
    assert_rejected([*common, "-o", tmp_path / "e.json"], "already exists", [store])
    assert (tmp_path / "e.json").read_text() == "{}"


@pytest.mark.parametrize("periodic", [False, "xyz"])
def test_a_step_showing_every_voxel_is_one_feature(periodic):
    """A threshold below every value (or a TF opaque everywhere) shows the whole volume: one
    feature of every voxel, its box the volume's, in Python and from the command line."""
    from chronocl.events.features import Mask, label_step, parse_periodic

    values = np.full((4, 5, 6), 2.0, np.float32)
    got = label_step(values, Mask.of_threshold(0.5), periodic=parse_periodic(periodic))
    assert len(got.features) == 1
    f = got.features[0]
    assert f.size == values.size
    graph = chronocl.events(np.stack([values, values]), threshold=0.5, periodic=periodic)
    assert [e["kind"] for e in graph.events] == ["continuation"]


def test_infinite_and_nan_values_are_never_shown():
    from chronocl.events.features import Mask

    values = np.array([[[np.inf, np.nan, 1.0, -np.inf]]], np.float32)
    assert Mask.of_threshold(0.5)(values).tolist() == [[[False, False, True, False]]]
    from chronocl.core.tf import DataTF

    opaque = Mask.of_tf(DataTF(), (0.0, 2.0), 0.0)
    assert not opaque(values)[0, 0, :2].any()


def test_a_periodic_axis_of_two_voxels_wraps_nothing():
    from chronocl.events.features import Mask, label_step

    values = np.zeros((2, 3, 7), np.float32)
    values[:, 1, 2:5] = 1.0
    got = label_step(values, Mask.of_threshold(0.5), periodic=(True, True, True))
    assert len(got.features) == 1 and "z" not in got.features[0].wraps


# -- markers in a render -----------------------------------------------------------------------
def test_markers_sit_where_the_events_happened():
    """A merge's marker is at the merged blob's centroid (fractions of the box), labelled with
    its kind and step; continuations get none; `steps` keeps the events of a window."""
    a = series(4)
    paint(a, 0, (2, 5), (1, 4))
    paint(a, 0, (2, 5), (10, 13))
    paint(a, 1, (2, 5), (3, 6))
    paint(a, 1, (2, 5), (8, 11))
    paint(a, 2, (2, 5), (4, 11))  # the merge: rows 2..4, columns 4..10 of the middle plane
    paint(a, 3, (2, 5), (5, 12))
    g = chronocl.events(a, threshold=0.5)
    ((where, label),) = g.markers()
    assert label == "merge 2"
    nz, ny, nx = SHAPE
    np.testing.assert_allclose(where, ((7 + 0.5) / nx, (3 + 0.5) / ny, (1 + 0.5) / nz))
    assert g.markers(range(2, 4)) == [] and g.markers(range(0, 3)) == g.markers()


@pytest.mark.filterwarnings("ignore::chronocl.core.errors.ChronoclWarning")  # an empty volume
def test_a_render_draws_each_marker_where_the_camera_sees_it():
    """A marker at the box's centre is drawn at the middle of the panel, in its colour, and
    nowhere else; one off the volume's side is left out when the camera does not see it."""
    from chronocl.render import Camera
    from chronocl.render.markers import MARKER_RGB

    a = np.zeros((3, 9, 9, 9), np.float32)
    cv = chronocl.integrate(chronocl.TimeSeries.from_array(a), "0:3", mode="max")
    camera = Camera(0.0, 0.0, 1.0, frame="box")
    plain = np.asarray(chronocl.render(cv, camera, (200, 160)).array)
    marked = np.asarray(
        chronocl.render(cv, camera, (200, 160), markers=[((0.5, 0.5, 0.5), "merge 3")]).array
    )
    changed = np.argwhere((plain != marked).any(axis=-1))
    assert len(changed) > 20
    (y0, x0), (y1, x1) = changed.min(axis=0), changed.max(axis=0)
    assert y0 <= 80 <= y1 and x0 <= 100 <= x1  # around the middle, label to its right
    assert (marked == MARKER_RGB).all(axis=-1).any()
    behind = chronocl.render(cv, camera, (200, 160), markers=[((0.5, 0.5, 40.0), "far")])
    np.testing.assert_array_equal(np.asarray(behind.array), plain)
    both = [((0.5, 0.5, 40.0), "far"), ((0.5, 0.5, 0.5), "merge 3")]  # one behind: the other
    np.testing.assert_array_equal(
        np.asarray(chronocl.render(cv, camera, (200, 160), markers=both).array), marked
    )


def test_cli_render_marks_the_window_s_events(store, tmp_path):
    out = tmp_path / "events.json"
    assert cli("events", store, "--threshold", "0.5", "-o", out, "--no-picture").returncode == 0
    plain, marked = tmp_path / "plain.png", tmp_path / "marked.png"
    base = ["render", store, "--mode", "max", "--window", "0:5", "--size", "160x120"]
    assert cli(*base, "-o", plain).returncode == 0
    result = cli(*base, "-o", marked, "--events", out)
    assert result.returncode == 0, result.stderr
    with Image.open(plain) as p, Image.open(marked) as m:
        assert p.size == m.size and np.asarray(p).tolist() != np.asarray(m).tolist()
    broken = json.loads(out.read_text())
    for e in broken["events"]:
        e.pop("step")
    (tmp_path / "broken.json").write_text(json.dumps(broken))
    other = json.loads(out.read_text())
    other["meta"]["volume_shape_zyx"] = [9, 9, 9]
    (tmp_path / "other.json").write_text(json.dumps(other))
    for events, needle in (
        ("missing.json", "does not exist"),
        ("broken.json", "not an events file"),
        ("other.json", "9x9x9 volume"),
    ):
        bad = cli(*base, "-o", tmp_path / "x.png", "--events", tmp_path / events)
        assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
        assert needle in bad.stderr and not (tmp_path / "x.png").exists()


def test_crowded_markers_keep_their_labels_apart_and_beside_their_rings(monkeypatch):
    """Forty markers on a few pixels (a Gray-Scott front's events from afar): every label drawn
    sits beside its own ring, on the panel, and overlaps no other; those with no room are left
    out (their rings stay). Before, a label with no room was drawn anyway, up to eight lines
    away, over the others."""
    from chronocl.render import Camera, markers

    drawn: list[tuple[float, float, tuple]] = []  # ring centre, label box
    spot = markers._label_spot

    def noting(bounds, px, py, radius, placed, size):
        found = spot(bounds, px, py, radius, placed, size)
        if found is not None:
            drawn.append((px, py, found[1]))
        return found

    monkeypatch.setattr(markers, "_label_spot", noting)
    a = np.zeros((3, 9, 9, 9), np.float32)
    cv = chronocl.integrate(chronocl.TimeSeries.from_array(a), "0:3", mode="max")
    rng = np.random.default_rng(4)
    crowd = [
        ((0.5 + d[0], 0.5 + d[1], 0.5), f"split {k}")
        for k, d in enumerate(rng.normal(0, 0.03, (40, 2)))
    ]
    size = (240, 200)
    chronocl.render(cv, Camera(0.0, 0.0, 1.0, frame="box"), size, markers=crowd)
    assert 3 <= len(drawn) < 40
    for i, (px, py, box) in enumerate(drawn):
        assert 0 <= box[0] and 0 <= box[1] and box[2] <= size[0] and box[3] <= size[1]
        near_x = min(abs(box[0] - px), abs(box[2] - px))
        assert near_x < 20 and box[1] - 60 < py < box[3] + 60, (px, py, box)  # beside its ring
        for other in drawn[i + 1 :]:
            assert not markers.boxes_overlap(box, other[2])


# -- worker processes: errors, Ctrl-C, a caller that dies, the memory plan (issue 51) ---------
class _TwoArgumentError(Exception):
    """An error whose __init__ takes more than its message: it pickles, but does not unpickle."""

    def __init__(self, path: str, step: int) -> None:
        super().__init__(f"{path} has no step {step}")


class _UnsendableError(Exception):
    """An error holding a lock: it does not pickle."""

    def __init__(self, path: str, step: int) -> None:
        super().__init__(f"{path} has no step {step}")
        self.lock = threading.Lock()


class _FailingSeries:
    """What a worker needs of a series, every read failing with `error` (the worker imports
    this module to unpickle it)."""

    volume_shape = (4, 5, 6)
    dtype = np.dtype(np.float32)

    def __init__(self, error: type[Exception]) -> None:
        self.error = error

    def read_brick(self, steps, out=None, per_call=1):
        raise self.error("/a/store", steps[0])


def _labellers(series, count: int = 1) -> events_processes.Labellers:
    axes = (False, False, False)
    return events_processes.Labellers(
        series, Mask.of_threshold(0.3), 26, axes, (1.0,) * 3, (0.0,) * 3, count
    )


@pytest.mark.parametrize(
    ("error", "needles"),
    [
        (_TwoArgumentError, ["did not unpickle", "_TwoArgumentError: /a/store has no step 2"]),
        (_UnsendableError, ["does not pickle", "_UnsendableError", "read_brick"]),
    ],
)
def test_a_worker_s_error_that_does_not_travel_fails_its_step_in_one_line(error, needles):
    """An error that does not unpickle in the caller, or pickle in the worker, still completes
    its step's Future (a find waiting on it would wait for ever) with a LabellingWorkerError
    naming it, in one line; the worker goes on answering."""
    with _labellers(_FailingSeries(error)) as workers:
        for step in (2, 3):
            with pytest.raises(events_processes.LabellingWorkerError) as info:
                workers.submit(step, None).result(timeout=60)
            text = str(info.value).replace(f"step {step}", "step 2")
            assert all(n in text for n in needles) and "\n" not in text, text


class _UnreachableSeries(_FailingSeries):
    """A series whose store a worker cannot reach as it unpickles it (an OSError)."""

    def __setstate__(self, state) -> None:
        raise FileNotFoundError("/a/store is gone")


def test_a_worker_whose_setup_fails_exits_as_failed(capfd):
    """A worker that cannot make its setup (a store out of reach) exits with its traceback
    and a failing code, not quietly with 0 (its error was taken for the caller's stdin
    closing), and leaves the other workers' folder alone."""
    with _labellers(_UnreachableSeries(OSError)) as workers:
        with pytest.raises(events_processes.LabellingWorkerError) as info:
            workers.submit(0, None).result(timeout=60)
        assert "(code 1)" in str(info.value), info.value
        assert Path(workers.folder).is_dir()
    assert "/a/store is gone" in capfd.readouterr().err


def test_a_worker_process_ignores_ctrl_c(tmp_path):
    """A Ctrl-C reaches the workers too (they share the caller's process group): they go on,
    and the caller ends them by closing."""
    import signal

    _stored_vortex(tmp_path / "v.zarr", 2)
    with _labellers(open_series(tmp_path / "v.zarr")) as workers:
        assert workers.submit(0, None).result(timeout=60).step == 0  # the worker is serving
        workers._procs[0].send_signal(signal.SIGINT)
        time.sleep(0.3)
        assert workers.submit(1, 0).result(timeout=60).shared is not None


CALLER = """
import sys, time
from chronocl.data.series import open_series
from chronocl.events.features import Mask
from chronocl.events.processes import Labellers
workers = Labellers(open_series(sys.argv[1]), Mask.of_threshold(0.3), 26, (False,) * 3,
                    (1.0,) * 3, (0.0,) * 3, 2)
workers.submit(0, None).result()
workers.submit(1, 5)  # waits for step 5, which never comes
print(workers.folder, flush=True)
time.sleep(600)
"""


def test_a_killed_caller_s_files_are_removed(tmp_path):
    """A caller killed (kill -9, out of memory) cannot remove its folder in /dev/shm: its
    workers do (one waiting for a step, one for its stdin), and a folder of a dead caller that
    still lies there is removed as the next workers start."""
    import signal
    import subprocess

    _stored_vortex(tmp_path / "v.zarr", 2)
    caller = subprocess.Popen(
        [sys.executable, "-c", CALLER, str(tmp_path / "v.zarr")], stdout=subprocess.PIPE, text=True
    )
    try:
        folder = Path(caller.stdout.readline().strip())
        assert folder.is_dir() and str(caller.pid) in folder.name
    finally:
        caller.send_signal(signal.SIGKILL)
        caller.wait()
    deadline = time.monotonic() + 30
    while folder.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not folder.exists()

    here = f"chronocl-events-{events_processes._here()}"
    stale = folder.parent / f"{here}-{caller.pid}-stale"  # as if its workers died too
    stale.mkdir()
    (stale / "0.voxels").write_bytes(b"\0" * 8)
    alive = folder.parent / f"{here}-{os.getpid()}-alive"
    alive.mkdir()
    # a dead pid of another host or PID namespace (a container sharing /dev/shm) says nothing
    elsewhere = folder.parent / f"chronocl-events-0000ffff-{caller.pid}-elsewhere"
    elsewhere.mkdir()
    try:
        with _labellers(open_series(tmp_path / "v.zarr")):
            pass
        assert not stale.exists() and alive.is_dir()  # a live caller's folder is its own
        assert elsewhere.is_dir()
    finally:
        for path in (stale, alive, elsewhere):
            shutil.rmtree(path, ignore_errors=True)


def test_steps_on_worker_processes_are_planned_for_what_a_worker_holds(tmp_path, monkeypatch):
    """A worker holds more a step than a thread does (`PROCESS_BYTES_PER_VOXEL`): a budget
    for two steps on threads but one on processes labels on threads; twice the workers' need
    labels on two processes; processes=False keeps a find on threads whatever the budget."""
    _stored_vortex(tmp_path / "v.zarr", 3)
    job = events_run.prepare(open_series(tmp_path / "v.zarr"), threshold=0.3)
    monkeypatch.setenv("CHRONOCL_THREADS", "2")
    monkeypatch.setattr(events_run, "PROCESS_MIN_VOXELS", 0)
    voxels = 20 * 24 * 28
    spent = events_run.Timings()
    events_run.find(job, timings=spent, memory=2 * voxels * (4 + 13))
    assert spent.processes == 0
    events_run.find(job, timings=spent, memory=2 * voxels * (4 + 57))
    assert spent.processes == 2
    events_run.find(job, timings=spent, memory=2 * voxels * (4 + 57), processes=False)
    assert spent.processes == 0


def test_periodic_labelling_keeps_within_the_bytes_a_voxel_its_step_is_planned_at():
    """Joining labels across periodic faces tracks the labels that face one another alone:
    tracking all of them (every speck of a noisy step) took 45 bytes a voxel, over the 13
    a step in flight is planned at (`events.run.THREAD_BYTES_PER_VOXEL`)."""
    import tracemalloc

    shown = np.random.default_rng(0).random((32, 32, 32)) < 0.15  # thousands of specks
    label(shown, 6, parse_periodic("xyz"))  # the libraries loaded, first
    tracemalloc.start()
    try:
        labels, _ = label(shown, 6, parse_periodic("xyz"))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert labels.max() > 1000
    assert peak <= events_run.THREAD_BYTES_PER_VOXEL * shown.size, peak / shown.size
