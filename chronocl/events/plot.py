"""A picture of an `EventGraph` (matplotlib, no display, no pyplot): the window's steps along x,
each step's features as bars stacked in its column (a bar's height is the feature's size, its
colour its track), the overlaps as lines between the bars of consecutive steps (solid in the
track's colour where the track goes on, dashed grey elsewhere, thicker for more similar
features), and the events other than continuations marked and named."""

from __future__ import annotations

import io
import os
from collections import defaultdict
from typing import Protocol

from chronocl.core.time_labels import display_labels, has_labels

BAR = 0.34  # a bar's width, in steps
GAP = 0.04  # between stacked bars, as a fraction of the tallest column
MAX_NAMED = 40  # more events than this are marked without their names
MAX_TRACK_NAMES = 30
# kind -> (marker, colour); continuations are left unmarked
MARKS = {
    "merge": ("v", "#d62728"),
    "split": ("^", "#1f77b4"),
    "merge-split": ("D", "#9467bd"),
    "birth": ("*", "#2ca02c"),
    "entry": ("P", "#17becf"),
    "death": ("X", "#222222"),
    "exit": ("s", "#ff7f0e"),
}


class Drawn(Protocol):
    """What the picture reads of an event graph (`chronocl.events.graph.EventGraph`, which
    draws itself through this module)."""

    features: list[dict]
    edges: list[dict]
    events: list[dict]
    tracks: list[dict]
    meta: dict

    def describe(self) -> str: ...


def mask_text(mask: dict) -> str:
    """What a step shows, as the meta's mask records it."""
    if mask.get("kind") == "threshold":
        return f"value ≥ {mask['threshold']:g}"
    lo, hi = mask.get("value_range", (0.0, 1.0))
    return f"TF opacity > {mask.get('opacity', 0):g} (values {lo:.4g} to {hi:.4g})"


def figure(graph: Drawn, title: str | None = None):
    """The picture as a matplotlib Figure (the module's docstring)."""
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    meta = graph.meta
    steps = list(meta.get("steps", sorted({f["step"] for f in graph.features})))
    column = {s: i for i, s in enumerate(steps)}
    by_step: dict[int, list[dict]] = defaultdict(list)
    for f in graph.features:
        by_step[f["step"]].append(f)
    tallest = max((sum(f["size"] for f in fs) for fs in by_step.values()), default=1)
    gap = GAP * tallest
    box: dict[tuple[int, int], tuple[float, float]] = {}  # (step, id) -> (bottom, height)
    for step, fs in by_step.items():
        y = 0.0
        for f in sorted(fs, key=lambda f: (f["track"], f["id"])):
            box[step, f["id"]] = (y, f["size"])
            y += f["size"] + gap
    # tab10's ten hues, then tab20's lighter ten: neighbouring tracks never share a hue; a
    # track has the colour a track-coloured render gives it (chronocl.events.palette)
    from chronocl.events.palette import track_rgb

    def colour(track: int):
        return track_rgb(track)

    width = min(16.0, max(7.0, 0.5 * len(steps) + 4.0))
    fig = Figure(figsize=(width, 6.0), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    track_of = {(f["step"], f["id"]): f["track"] for f in graph.features}
    for e in graph.edges:
        a, b = tuple(e["source"]), tuple(e["target"])
        (ya, ha), (yb, hb) = box[a], box[b]
        same = track_of[a] == track_of[b]
        ax.plot(
            [column[a[0]] + BAR / 2, column[b[0]] - BAR / 2],
            [ya + ha / 2, yb + hb / 2],
            color=colour(track_of[a]) if same else "0.55",
            linestyle="-" if same else "--",
            linewidth=0.8 + 3.2 * e["similarity"],
            alpha=0.9 if same else 0.7,
            zorder=1,
        )
    for (step, fid), (y, h) in box.items():
        ax.bar(
            column[step],
            h,
            BAR,
            y,
            color=colour(track_of[step, fid]),
            edgecolor="0.2",
            linewidth=0.6,
            zorder=2,
        )
    if len(graph.tracks) <= MAX_TRACK_NAMES:
        for t in graph.tracks:
            step, fid = t["features"][0]
            y, h = box[step, fid]
            ax.text(
                column[step] - BAR / 2 - 0.04,
                y + h / 2,
                f"T{t['id']}",
                ha="right",
                va="center",
                fontsize=8,
                color="0.25",
                zorder=3,
            )
    _mark_events(ax, graph, column, box, gap)

    times = meta.get("times") or steps
    named = has_labels(steps, times, meta.get("time_unit"))
    ticks = display_labels(steps, times, unit=meta.get("time_unit"))
    every = max(1, len(steps) // 24)
    ax.set_xticks(range(0, len(steps), every))
    ax.set_xticklabels(
        [f"{steps[i]}\n{ticks[i]}" if named else ticks[i] for i in range(0, len(steps), every)],
        fontsize=8,
    )
    ax.set_xlabel("step and time" if named else "step")
    ax.set_ylabel("feature size (voxels, stacked per step)")
    ax.set_xlim(-0.8, len(steps) - 0.2)
    top = max((y + h for y, h in box.values()), default=1.0)
    ax.set_ylim(0, top * 1.12 + gap)
    ax.spines[["top", "right"]].set_visible(False)
    present = [k for k in MARKS if any(e["kind"] == k for e in graph.events)]
    handles = [
        Line2D([], [], marker=MARKS[k][0], color=MARKS[k][1], linestyle="", markersize=8, label=k)
        for k in present
    ]
    handles.append(Line2D([], [], color="0.3", linewidth=2, label="overlap, same track"))
    handles.append(
        Line2D([], [], color="0.55", linestyle="--", linewidth=2, label="overlap, other track")
    )
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    where = meta.get("source") or "series"
    how = (
        f"{mask_text(meta.get('mask', {}))}, {meta.get('connectivity', 26)}-connected"
        + (f", periodic {meta['periodic']}" if meta.get("periodic") else "")
        + f", {meta.get('tracks_method', '')} tracks"
    )
    ax.set_title(title or f"{where}: {graph.describe()}\n{how}", fontsize=10)
    return fig


def _mark_events(ax, graph: Drawn, column: dict, box: dict, gap: float) -> None:
    """A marker (and, for few events, the kind's name) where each event happens."""
    marked = [e for e in graph.events if e["kind"] in MARKS]
    for e in marked:
        marker, colour = MARKS[e["kind"]]
        if e["targets"] and e["kind"] != "split":  # at the bars it led to, on their left
            step, ids, dx = e["next_step"], e["targets"], -BAR / 2
        else:  # a split, death or exit: at the bars it came from, on their right
            step, ids, dx = e["step"], e["sources"], BAR / 2
        spans = [box[step, i] for i in ids]
        y = max(b + h for b, h in spans)
        x = column[step] + dx
        ax.plot(x, y + gap / 2, marker=marker, color=colour, markersize=9, zorder=4)
        if len(marked) <= MAX_NAMED:
            ax.annotate(
                e["kind"],
                (x, y + gap / 2),
                xytext=(0, 7),
                textcoords="offset points",
                ha="center",
                fontsize=8,
                color=colour,
                zorder=5,
                # on a white ground: a name would vanish over a bar of its own colour
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.85},
            )


def png_bytes(graph: Drawn, title: str | None = None) -> bytes:
    """The picture as PNG bytes (Agg), drawn whole before anything is written."""
    buffer = io.BytesIO()
    figure(graph, title).savefig(buffer, format="png")
    return buffer.getvalue()


def write_png(data: bytes, path: str | os.PathLike, overwrite: bool = False) -> None:
    """Write PNG bytes (`png_bytes`) to `path` atomically."""
    from chronocl.core.atomic import atomic_file

    with atomic_file(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(data)
