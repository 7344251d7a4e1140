"""Matching features through time: overlaps, events (Silver & Wang) and tracks (local, global).

The features of two consecutive steps of the window are matched by voxel overlap: an edge joins
feature a of step t and feature b of step t+1 wherever they share a voxel, weighted by their
**similarity**, the Jaccard index |a ∩ b| / |a ∪ b| (in (0, 1], 1 for the same voxels): it is
symmetric, so a split and a merge are weighed alike, and it falls as a feature grows, shrinks
or moves.

**Events** (after Silver & Wang 1997) are read per connected group of the bipartite overlap
graph between t and t+1, n features of t and m of t+1:

- 1 -> 1 continuation, n -> 1 merge, 1 -> m split, n -> m merge-split (n, m >= 2);
- 1 -> 0 death, or **exit** when the feature touched the volume's boundary at t (it left
  through a face); 0 -> 1 birth, or **entry** when the new feature touches the boundary.

`at_boundary` says whether any feature of the event touches the boundary. The window's first
step has no births and its last no deaths: what lies outside the window is unknown.

**Tracks** give every feature one track id; two methods:

- ``local``: per pair of steps, the edges in decreasing similarity (then overlap) each link
  their two features when neither is linked yet on that side: each feature continues along its
  largest overlap that is still free, a decision taken per pair of steps.
- ``global`` (after Saikia & Weinkauf 2017): tracks are cheapest paths through the whole
  window's DAG, an edge costing 1 - similarity and each window step a path does not cover
  costing 1, so a path's cost is W - 1 - (the sum of its similarities) over a window of W
  steps. They are taken greedily: the cheapest path of each weakly connected part of the
  graph (networkx's Dijkstra from a source joined to every feature to a sink joined from
  every feature, the joins costing the steps they skip), its features removed, again until
  every feature has a track. A step where the overlap dips, while a rival briefly overlaps
  more, then does not break a track that goes on afterwards, where local matching follows
  the rival and loses it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from chronocl.core.errors import UnknownNameError
from chronocl.events import extra
from chronocl.events.features import Feature

SIMILARITY = "jaccard"
TRACK_METHODS = ("global", "local")
EVENT_KINDS = (
    "continuation",
    "merge",
    "split",
    "merge-split",
    "birth",
    "entry",
    "death",
    "exit",
)
Node = tuple[int, int]  # (series step, feature id)


def check_method(method: object) -> str:
    """'global' or 'local', else one line naming them."""
    if method not in TRACK_METHODS:
        raise UnknownNameError(
            f"unknown track method {method!r}; choose global (cheapest paths through the whole "
            "window) or local (each step pair's largest overlaps)"
        )
    return str(method)


@dataclass(frozen=True)
class Edge:
    """Feature `source` of one step overlaps feature `target` of the next in `overlap` voxels."""

    source: Node
    target: Node
    overlap: int
    similarity: float

    def to_dict(self) -> dict:
        return {
            "source": list(self.source),
            "target": list(self.target),
            "overlap": self.overlap,
            "similarity": self.similarity,
        }


@dataclass(frozen=True)
class Event:
    """What happened between `step` and `next_step` to features `sources` (ids at `step`),
    which became `targets` (ids at `next_step`)."""

    kind: str
    step: int
    next_step: int
    sources: tuple[int, ...]
    targets: tuple[int, ...]
    at_boundary: bool

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "step": self.step,
            "next_step": self.next_step,
            "sources": list(self.sources),
            "targets": list(self.targets),
            "at_boundary": self.at_boundary,
        }


CHUNK = 1 << 22  # voxels of `a`'s features compared at once: small temporaries on dense steps


def overlaps(
    a: np.ndarray | None,
    b: np.ndarray,
    a_voxels: np.ndarray | None = None,
    a_owners: np.ndarray | None = None,
) -> dict[tuple[int, int], int]:
    """Voxels shared by each pair (label of `a`, label of `b`) of two label arrays.

    `a_voxels`, the flat indices of `a`'s labelled voxels (`StepFeatures.voxels`), spares a
    scan of both whole arrays: only those voxels are looked up in `b`. `a_owners`, given with
    them, are `a`'s labels there (in their order): `a` itself is then not needed (None)."""
    if a_voxels is None:
        assert a is not None
        a_voxels = np.flatnonzero(a)
    flat_b = b.reshape(-1)
    shared: dict[tuple[int, int], int] = {}
    for start in range(0, a_voxels.size, CHUNK):
        where = a_voxels[start : start + CHUNK]
        if a_owners is None:
            assert a is not None
            owners = a.reshape(-1)[where]
        else:
            owners = a_owners[start : start + CHUNK]
        there = flat_b[where]
        both = there > 0
        keys = (owners[both].astype(np.uint64) << np.uint64(32)) | there[both].astype(np.uint64)
        found, counts = np.unique(keys, return_counts=True)
        for k, c in zip(found.tolist(), counts.tolist(), strict=True):
            pair = (int(k >> 32), int(k & 0xFFFFFFFF))
            shared[pair] = shared.get(pair, 0) + int(c)
    return shared


def similarity(overlap: int, size_a: int, size_b: int) -> float:
    """The Jaccard index of two features sharing `overlap` voxels."""
    return overlap / (size_a + size_b - overlap)


def link(
    step: int,
    labels: np.ndarray,
    features: Sequence[Feature],
    next_step: int,
    next_labels: np.ndarray,
    next_features: Sequence[Feature],
    voxels: np.ndarray | None = None,
) -> list[Edge]:
    """The overlap edges from the features of `step` to those of `next_step` (`voxels`: the
    flat indices of the voxels `labels` labels, where known: `overlaps`)."""
    shared = overlaps(labels, next_labels, voxels)
    return edges_of(step, features, next_step, next_features, shared)


def edges_of(
    step: int,
    features: Sequence[Feature],
    next_step: int,
    next_features: Sequence[Feature],
    shared: dict[tuple[int, int], int],
) -> list[Edge]:
    """The edges of two steps' features that share voxels (`shared`: `overlaps`), in order."""
    size = {f.id: f.size for f in features}
    next_size = {f.id: f.size for f in next_features}
    return [
        Edge((step, a), (next_step, b), n, similarity(n, size[a], next_size[b]))
        for (a, b), n in sorted(shared.items())
    ]


def classify(
    step: int,
    next_step: int,
    features: Sequence[Feature],
    next_features: Sequence[Feature],
    edges: Sequence[Edge],
) -> list[Event]:
    """The events between two consecutive steps of the window, one per connected group of
    their overlap graph (`edges`), sources first, then births."""
    nx = extra.networkx()
    g = nx.Graph()
    g.add_nodes_from((0, f.id) for f in features)
    g.add_nodes_from((1, f.id) for f in next_features)
    g.add_edges_from(((0, e.source[1]), (1, e.target[1])) for e in edges)
    edge_of = {f.id: f.touches_boundary for f in features}
    next_edge_of = {f.id: f.touches_boundary for f in next_features}
    found = []
    for group in nx.connected_components(g):
        sources = tuple(sorted(i for side, i in group if side == 0))
        targets = tuple(sorted(i for side, i in group if side == 1))
        boundary = any(edge_of[i] for i in sources) or any(next_edge_of[i] for i in targets)
        n, m = len(sources), len(targets)
        if m == 0:
            kind = "exit" if boundary else "death"
        elif n == 0:
            kind = "entry" if boundary else "birth"
        elif n == 1 and m == 1:
            kind = "continuation"
        elif m == 1:
            kind = "merge"
        elif n == 1:
            kind = "split"
        else:
            kind = "merge-split"
        found.append(Event(kind, step, next_step, sources, targets, boundary))
    # sources first (by their first id), then the births (by their first target)
    found.sort(key=lambda e: (not e.sources, e.sources[:1] or e.targets[:1]))
    return found


# -- tracks ------------------------------------------------------------------------------------
def local_tracks(nodes: Sequence[Node], edges: Sequence[Edge]) -> list[list[Node]]:
    """Tracks by local matching: per pair of steps, the edges by decreasing similarity (then
    overlap) link their features where both are still free on that side."""
    ahead: dict[Node, Node] = {}
    behind: dict[Node, Node] = {}
    ranked = sorted(edges, key=lambda e: (-e.similarity, -e.overlap, e.source, e.target))
    for e in ranked:
        if e.source not in ahead and e.target not in behind:
            ahead[e.source], behind[e.target] = e.target, e.source
    tracks = []
    for node in sorted(nodes):
        if node in behind:
            continue
        track = [node]
        while track[-1] in ahead:
            track.append(ahead[track[-1]])
        tracks.append(track)
    return tracks


def global_tracks(
    nodes: Sequence[Node], edges: Sequence[Edge], steps: Sequence[int]
) -> list[list[Node]]:
    """Tracks as the cheapest paths through the window's DAG (the module's docstring), taken
    greedily: per weakly connected part, the cheapest path, then again on what is left."""
    nx = extra.networkx()
    position = {s: i for i, s in enumerate(steps)}
    last = len(steps) - 1
    dag = nx.DiGraph()
    dag.add_nodes_from(sorted(nodes))
    for e in sorted(edges, key=lambda e: (e.source, e.target)):
        dag.add_edge(e.source, e.target, cost=max(0.0, 1.0 - e.similarity))
    tracks = []
    parts = [sorted(c) for c in nx.weakly_connected_components(dag)]
    while parts:
        part = parts.pop()
        if len(part) == 1:
            tracks.append(part)
            continue
        paths = dag.subgraph(part).copy()
        source, sink = "source", "sink"
        for node in part:  # joining at step i skips i steps; leaving at i skips last - i
            paths.add_edge(source, node, cost=float(position[node[0]]))
            paths.add_edge(node, sink, cost=float(last - position[node[0]]))
        path = nx.dijkstra_path(paths, source, sink, weight="cost")[1:-1]
        tracks.append(path)
        rest = dag.subgraph(set(part) - set(path))
        parts += [sorted(c) for c in nx.weakly_connected_components(rest)]
    return sorted(tracks)


def tracks_of(
    method: str, nodes: Sequence[Node], edges: Sequence[Edge], steps: Sequence[int]
) -> list[list[Node]]:
    """The tracks by `method` ('global' or 'local'), ordered by their first feature."""
    if check_method(method) == "local":
        return sorted(local_tracks(nodes, edges))
    return global_tracks(nodes, edges, steps)
