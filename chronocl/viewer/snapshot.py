"""A snapshot: the viewer's state saved as one versioned JSON object holding everything a
frame depends on, so a view found interactively becomes a reproducible figure. (Not the
integration `Session`, nor the page's undo history: static/history.js.)

Users see it as a "session file": the viewer's Save session writes it, Load session and the
page's URL fragment (`#state=...`, the same object) apply it as one step, and `chronocl
render --state FILE` draws it; the file format keeps that name (its `chronocl_session` key,
`SESSION_VERSION`, `NAME-session.json`), so files saved before read the same. Its fields are
the state fields of the protocol's update message (checked by `protocol.SNAPSHOT`) plus the
format's version and the data set:

    {"chronocl_session": 1,
     "dataset": {"name": "vortex", "path": "/data/vortex.zarr", "shape": [30, 96, 96, 96]},
     "window": {"t0": 10, "t1": 20, "stride": 1},
     "views": [{"mode": "alpha", "order": "forward", "window": null, "camera": null,
                "data_tf": null, "time_tf": null},
               {"mode": "alpha", "order": "forward", "window": {"t0": 40, "t1": 50},
                "camera": {"azimuth": 120, "elevation": -10, "zoom": 1.5, ...},
                "data_tf": null, "time_tf": {"alpha": "hat", ...}}],
     "camera": {"azimuth": 30, "elevation": 20, "zoom": 1.2, "fov": 30,
                "projection": "perspective", "up": "y"},
     "data_tf": {"points": [[0, 1, 1, 1, 0], [1, 1, 1, 1, 0.9]]},
     "time_tf": {"color": "rgb", "alpha": "hat", "center": 0.5, "width": 0.6, ...},
     "enhance": {"kind": "none"}, "threshold": 0.05, "clip": null,
     "size": [512, 512], "background": "black", "outline": false,
     "shading": {"enabled": false, ...}, "focus": [-0.3, -0.4, -0.5, 0.3, 0.4, 0.5]}

A view's `window`, `camera`, `data_tf` and `time_tf` are its own (to compare two periods, two
viewpoints or two colourings side by side); null (or left out) follows the shared one (linked).
An own camera frames the shared camera's focus. Enhancement and lighting are shared by the
views. `focus` is the world box the camera framed (the viewer frames the visible region
of a data set's first frame, or of the frame after a camera reset, and keeps it while the
window moves); null frames the visible region of the snapshot's own chronovolumes.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path

from chronocl.core.errors import InputNotFoundError, InvalidParameterError, InvalidSelectionError
from chronocl.data.series import TimeSeries
from chronocl.render.framing import framed
from chronocl.render.image import Image
from chronocl.render.triad import draw_triad
from chronocl.render.views import parse_color, raycaster
from chronocl.viewer.box_axes import draw_axes, views_axes
from chronocl.viewer.datasets import Dataset, find_dataset
from chronocl.viewer.protocol import (
    LIMITS,
    SESSION_KEY,
    SESSION_VERSION,
    SNAPSHOT,
    decode_json,
)
from chronocl.viewer.saving import Downloads, picture
from chronocl.viewer.schema import ProtocolError
from chronocl.viewer.view_state import ViewState, default_state, describe_state, merge

# The fields `merge` applies (the rest: version, data set, shading).
STATE_FIELDS = (
    "window",
    "views",
    "camera",
    "data_tf",
    "time_tf",
    "enhance",
    "threshold",
    "clip",
    "size",
    "background",
    "outline",
    "shading",
)


class SnapshotFileError(InvalidParameterError):
    """A snapshot (session) file that cannot be read, is not one, or is of another version."""


def snapshot_of(
    state: ViewState,
    name: str,
    series: TimeSeries,
    path: str | None = None,
    focus: Sequence[float] | None = None,
) -> dict:
    """The snapshot's object for `state` on the data set `name` (stored at `path`), its
    views framing the world box `focus` (None: their visible region)."""
    described = describe_state(state)  # a fitted data TF with its value range
    dataset = {"name": name, "shape": list(series.shape)}
    if path is not None:
        dataset["path"] = str(path)
    return {
        SESSION_KEY: SESSION_VERSION,
        "dataset": dataset,
        **{k: described[k] for k in STATE_FIELDS},
        "focus": None if focus is None else [float(v) for v in focus],
    }


def check_snapshot(obj: object, where: str = "session") -> dict:
    """The validated snapshot object; raises SnapshotFileError naming the first bad field."""
    if not isinstance(obj, dict) or SESSION_KEY not in obj:
        raise SnapshotFileError(
            f"{where} is not a chronocl session (no {SESSION_KEY!r} field); "
            "save one with the viewer's Save session button"
        )
    try:
        return SNAPSHOT.check(obj, "session")  # "session": the name its errors give
    except ProtocolError as exc:
        raise SnapshotFileError(f"{where}: {exc}") from None


def read_snapshot(path: str | os.PathLike) -> dict:
    """A snapshot file read and validated (SnapshotFileError or InputNotFoundError, one line)."""
    p = Path(path)
    if not p.is_file():
        raise InputNotFoundError(f"session file {str(p)!r} not found; save one in the viewer")
    if p.stat().st_size > LIMITS.session_file_bytes:
        raise SnapshotFileError(
            f"{p.name} is over {LIMITS.session_file_bytes >> 20} MiB: not a session file"
        )
    try:
        obj = decode_json(p.read_text(encoding="utf-8"))
    except (ProtocolError, ValueError) as exc:  # UnicodeDecodeError and JSON errors too
        raise SnapshotFileError(f"{p.name} is not valid JSON ({exc})") from None
    return check_snapshot(obj, p.name)


def write_snapshot(snapshot: dict) -> bytes:
    """The snapshot as JSON text, one top-level field a line."""
    lines = [f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in snapshot.items()]
    return ("{\n" + ",\n".join(lines) + "\n}\n").encode()


def apply_snapshot(state: ViewState, snapshot: dict, n_steps: int) -> ViewState:
    """`state` with every state field of a validated snapshot applied (one step: nothing is
    applied when a field does not fit the data set)."""
    fields = {k: snapshot[k] for k in STATE_FIELDS if k in snapshot}
    if "shading" in fields and fields["shading"] is None:  # null: the lighting as it is
        del fields["shading"]
    try:
        return merge(state, fields, n_steps)
    except InvalidSelectionError as exc:  # a window beyond the series' steps
        raise SnapshotFileError(f"the session does not fit its data set: {exc}") from None


def loaded_state(
    datasets: list[Dataset], state: ViewState, snapshot: dict
) -> tuple[int, ViewState]:
    """The data set a validated snapshot names (by name, else by path) and the state it
    describes there: `state` with the snapshot applied when that data set is shown, else the
    data set's defaults with it applied."""
    ds = snapshot["dataset"]
    i = find_dataset(datasets, ds["name"], ds.get("path"))
    series = datasets[i].series
    base = state if i == state.dataset else default_state(i, series)
    return i, apply_snapshot(base, snapshot, series.n_steps)


def checked_focus(state: ViewState, box: Sequence[float] | None) -> tuple | None:
    """`box` as a camera focus (ChronoclError naming the problem), or None."""
    if box is None:
        return None
    return dataclasses.replace(state.camera, focus=tuple(box)).focus


def save_snapshot(
    downloads: Downloads, state: ViewState, ds: Dataset, focus: Sequence[float] | None = None
) -> tuple[str, str]:
    """`state` (framing `focus`) as a snapshot (session file) download; returns its key and name."""
    name = f"{ds.name}-session.json"
    body = write_snapshot(snapshot_of(state, ds.name, ds.series, ds.path, focus))
    return downloads.add(body, name, "application/json"), name


def snapshot_state(snapshot: dict, series: TimeSeries) -> ViewState:
    """The viewer state a snapshot describes on `series` (the viewer's defaults elsewhere), its
    camera framing the snapshot's focus."""
    state = apply_snapshot(default_state(0, series), snapshot, series.n_steps)
    focus = checked_focus(state, snapshot.get("focus"))
    return dataclasses.replace(state, camera=dataclasses.replace(state.camera, focus=focus))


def dataset_path(snapshot: dict, where: str) -> Path:
    """The store a snapshot names (`dataset.path`), which must exist."""
    path = snapshot["dataset"].get("path")
    if path is None:
        raise SnapshotFileError(
            f"{where} names the data set {snapshot['dataset']['name']!r} but not its path; "
            "give the store on the command line"
        )
    return Path(path)


def render_snapshot(
    state: ViewState,
    series: TimeSeries,
    *,
    engine: str = "opencl",
    device: str | None = None,
    time_labels: str = "labels",
    axes: bool = False,
    name: str | None = None,
    changes: Sequence[dict] = (),
) -> Image:
    """The views of `state` drawn as the viewer's Save PNG draws them: the same chronovolumes,
    camera (as the panels are drawn, framing its focus, else the visible region), size, clip,
    lighting, background and outline (with its labelled axes), each panel labelled, its
    legends below, and with the data set's `name` Save PNG's title band over them, naming it
    and the windows (also the PNG's Title text); `axes` adds the axis triad to each panel
    (`chronocl render --state --axes`).
    `changes[i]` replaces fields of view i's IntegrationSpec (e.g. a time TF given on the
    command line, a colour map given to its own data TF)."""
    from chronocl.integration.inmemory import integrate

    specs = [
        dataclasses.replace(state.spec(i), **(changes[i] if i < len(changes) else {}))
        for i in range(len(state.views))
    ]
    cvs = [
        integrate(series, state.selection(series.n_steps, i), spec=s, engine=engine, device=device)
        for i, s in enumerate(specs)
    ]
    state = dataclasses.replace(state, camera=framed(state.camera, cvs))
    rc = raycaster()
    bg = parse_color(state.background)
    labelled = views_axes(state, cvs, series)  # the box axes (`axes` is the triad)
    panels = []
    for i, cv in enumerate(cvs):
        volume = rc.upload(cv)
        try:
            panels.append(
                rc.draw(
                    volume,
                    state.panel_camera(i),  # its own camera where it has one
                    state.size,
                    background=bg,
                    clip=state.clip,
                    step=1.0,
                    outline=state.outline,
                    shading=state.shading,
                )
            )
            if labelled is not None:  # the box's labelled axes, as Save PNG draws them
                panels[-1] = draw_axes(panels[-1], labelled[i])
            if axes:
                panels[-1] = draw_triad(panels[-1], state.panel_camera(i))
        finally:
            volume.release()
    return picture(panels, cvs, bg, None, name, time_labels)[0]
