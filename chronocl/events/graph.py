"""`EventGraph`: the features of a window, their overlaps, events and tracks, as records, as a
networkx graph and as JSON.

The records are plain lists of dicts (what the JSON holds): `features` (one per feature of
each step, with its track), `edges` (overlaps between consecutive steps), `events` and
`tracks`; `meta` says how they were found (the window's steps and times, the mask, the
connectivity, the periodic axes, the similarity measure and the track method). `graph` is the
same as an `nx.DiGraph` whose nodes are (step, feature id) with the feature's fields as
attributes and whose edges carry overlap and similarity; `to_pandas` gives a DataFrame per
record list. `save` writes the JSON atomically; `EventGraph.load` (`load_events`) reads it back.
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidDataError
from chronocl.events import extra

FORMAT = "chronocl-events"
VERSION = 1
RECORDS = ("features", "edges", "events", "tracks")
MAX_JSON_BYTES = 1 << 30  # an events file larger than this is not one


@dataclass
class EventGraph:
    """Features, overlap edges, events and tracks of a window of steps (the module's docstring)."""

    features: list[dict]
    edges: list[dict]
    events: list[dict]
    tracks: list[dict]
    meta: dict = field(default_factory=dict)

    # -- views -------------------------------------------------------------------------------
    @property
    def graph(self):
        """The event graph as a new `nx.DiGraph`: nodes (step, id) with the features' fields,
        edges with overlap and similarity; the graph's own attributes are `meta`."""
        nx = extra.networkx()
        g = nx.DiGraph(**self.meta)
        for f in self.features:
            g.add_node((f["step"], f["id"]), **f)
        for e in self.edges:
            g.add_edge(
                tuple(e["source"]),
                tuple(e["target"]),
                overlap=e["overlap"],
                similarity=e["similarity"],
            )
        return g

    @property
    def method(self) -> str:
        """The track method the tracks were found with ('global' or 'local')."""
        return self.meta.get("tracks_method", "")

    def counts(self) -> dict[str, int]:
        """How many events of each kind, continuations included, in a fixed order."""
        from chronocl.events.tracking import EVENT_KINDS

        seen = Counter(e["kind"] for e in self.events)
        return {k: seen[k] for k in EVENT_KINDS if seen[k]}

    def describe(self) -> str:
        """One line: features, steps, tracks and the events other than continuations."""
        counts = self.counts()
        counts.pop("continuation", None)
        happened = ", ".join(f"{n} {k}" for k, n in counts.items()) or "no events"
        steps = len(self.meta.get("steps", ()))
        return (
            f"{_count(len(self.features), 'feature')} over {_count(steps, 'step')}, "
            f"{_count(len(self.tracks), 'track')} ({self.method}); {happened}"
        )

    def figure(self, title: str | None = None):
        """A picture of the graph as a matplotlib Figure (`chronocl.events.plot`): steps on x,
        features as bars as tall as their size, overlaps as lines, events marked."""
        from chronocl.events.plot import figure

        return figure(self, title)

    def save_picture(
        self, path: str | os.PathLike, overwrite: bool = False, title: str | None = None
    ) -> Path:
        """Write the picture (`figure`) as a PNG, atomically."""
        from chronocl.events.plot import png_bytes, write_png

        write_png(png_bytes(self, title), path, overwrite)
        return Path(path)

    def markers(
        self, steps=None, limit: int | None = None
    ) -> list[tuple[tuple[float, float, float], str]]:
        """The events other than continuations as markers for a render (`chronocl.render`'s
        `markers=`): where each happened, as (x, y, z) fractions of the volume's box, and a
        label ("merge 12": the kind and the step it happened at). A birth, entry, merge, split
        or merge-split is placed at its new features' centroid (size-weighted), a death or exit
        at the last centroid of those that went. `steps`: only events within their span (e.g.
        a rendered window's, any stride), else all; `limit`: at most that many (the first)."""
        return [
            (fractions, f"{e['kind']} {e['next_step'] if e['targets'] else e['step']}")
            for e, fractions in self.places(steps, limit)
        ]

    def places(
        self, steps=None, limit: int | None = None
    ) -> list[tuple[dict, tuple[float, float, float]]]:
        """Each event other than a continuation with where it happened, (x, y, z) fractions
        of the volume's box (as `markers` places it); `steps` and `limit` as for `markers`."""
        shape = self.meta.get("volume_shape_zyx")
        if not shape:
            return []
        at = {(f["step"], f["id"]): f for f in self.features}
        span = None if steps is None else (min(steps), max(steps))
        out = []
        for e in self.events:
            if limit is not None and len(out) >= limit:
                break
            if e["kind"] == "continuation":
                continue
            if span is not None and not span[0] <= e["step"] < e["next_step"] <= span[1]:
                continue
            step, ids = (
                (e["next_step"], e["targets"]) if e["targets"] else (e["step"], e["sources"])
            )
            feats = [at[step, i] for i in ids if (step, i) in at]
            if not feats:
                continue
            sizes = np.array([f["size"] for f in feats], dtype=np.float64)
            zyx = np.array([f["centroid_zyx"] for f in feats], dtype=np.float64)
            centre = (sizes[:, None] * zyx).sum(axis=0) / sizes.sum()
            fractions = (centre[::-1] + 0.5) / np.asarray(shape[::-1], dtype=np.float64)
            out.append((e, tuple(float(v) for v in fractions)))
        return out

    def to_pandas(self) -> dict:
        """A pandas DataFrame per record list: features, edges, events, tracks."""
        import pandas as pd

        return {name: pd.DataFrame.from_records(getattr(self, name)) for name in RECORDS}

    # -- JSON --------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "meta": self.meta,
            **{name: getattr(self, name) for name in RECORDS},
        }

    def to_json(self, indent: int | None = 1) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    def save(self, path: str | os.PathLike, overwrite: bool = False) -> Path:
        """Write the JSON to `path` atomically (a hidden sibling renamed when complete)."""
        from chronocl.core.atomic import atomic_file

        text = self.to_json() + "\n"
        with atomic_file(path, overwrite=overwrite) as tmp:
            tmp.write_text(text, encoding="utf-8")
        return Path(path)

    @classmethod
    def from_dict(cls, d: object, where: str = "events JSON") -> EventGraph:
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise InvalidDataError(
                f'{where} is not a chronocl events file (no "format": "{FORMAT}"); '
                "write one with 'chronocl events' or EventGraph.save"
            )
        if d.get("version") != VERSION:
            raise InvalidDataError(
                f"{where} is version {d.get('version')!r} of the events format; this chronocl "
                f"reads version {VERSION}"
            )
        bad = [n for n in RECORDS if not isinstance(d.get(n), list)]
        if bad or not isinstance(d.get("meta"), dict):
            missing = ", ".join(bad) or "meta"
            raise InvalidDataError(f"{where} lacks its {missing}; write it again")
        return cls(**{n: d[n] for n in RECORDS}, meta=d["meta"])

    @classmethod
    def load(cls, path: str | os.PathLike) -> EventGraph:
        """Read an events JSON written by `save` (or `chronocl events`)."""
        from chronocl.core.paths import check_input

        p = check_input(path, "events file", want="file", hint="check the path")
        if p.stat().st_size > MAX_JSON_BYTES:
            raise InvalidDataError(f"{p.name} is larger than an events file can be; check it")
        try:
            d = json.loads(p.read_text(encoding="utf-8"), parse_constant=_no_constant)
        except (json.JSONDecodeError, UnicodeDecodeError, ValueError) as exc:
            raise InvalidDataError(f"{p.name} is not valid JSON ({exc}); fix the file") from None
        return cls.from_dict(d, p.name)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a JSON number")


def load_events(path: str | os.PathLike) -> EventGraph:
    """`EventGraph.load`."""
    return EventGraph.load(path)


def jsonable(value: object) -> object:
    """A time label as JSON holds it: numbers and strings as they are, anything else as text."""
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, int | str):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating) and math.isfinite(float(value)):
        return float(value)
    return str(value)
