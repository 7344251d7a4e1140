"""The viewer's WebSocket protocol: message schemas and their validation.

Client -> server messages are JSON objects of at most `LIMITS.message_bytes`, each with a
`type` and an optional request `id` (echoed in replies and frames):

    open       {"dataset": index or name[, "fit"]}      switch data set (defaults reset; the
                                                         TF fitted unless "fit" is false)
    update     camera, views, window, data_tf, time_tf,  any subset; the server merges it
               enhance, threshold, clip, size, quality,  into the client's state and renders
               background, outline, shading, refocus,    the newest state only (refocus:
               focus                                     frame the visible region again;
                                                         focus: frame this world box)
    probe      {"view", "x", "y"[, "x2", "y2"]}         x, y in [0, 1] of the panel, top-left 0;
                                                         x2, y2: a box between two rays' voxels
               {"view", "slice", "u", "v"}              or pinned on a slice ("z=40") at (u, v)
                                                         of its voxel grid (reply: "pinned")
    histogram  {"range": [lo, hi]}                       normalised values u in the window
               (+ "view": the view's own window; "of": "change", "value_range": [lo, hi]:
               the changes between its steps)
    fit        {"view"[, "mode"]}                       the TF's range fitted to a view's window
    slice      {"slice", "view"[, "u", "v"]}             a plane of a view ("z=40") as a PNG, and
                                                         the winner at (u, v) of its voxel grid
    save       {"what": "image" | "chronovolume", "view"} the image's download also gives its
                                                         `layout` (title, captions, pictures,
                                                         legends: [x, y, w, h] in pixels)
               {"what": "movie", "movie": orbit | play,   a video download, a `progress`
                "format": mp4 | gif, "frames", "fps"}     message after every frame
               {"what": "session"}                       the state as a snapshot file
    load       {"session": a snapshot's object}         apply a snapshot as one step
    cancel     {}                                       stop refining the frame shown
    events     {"action": "find", "view"[, "by":        the features, events and tracks of the
                "opacity" | "value", "opacity" | "value", view's window (`events_panel`), found
                "connectivity", "show"]}                  beside the frames: `progress` after a
                                                         second, then an `events` reply (given
                                                         up when the window changes); show:
                                                         their markers drawn once found
               {"action": "markers", "show": bool}       draw the found events in the frames
               {"action": "track", "track": id | null   draw that track's path in them too
                [, "find": the find's id]}               (ignored: another find's list)
               {"action": "clear"}                       forget them (no markers)

Every field is checked against its schema: unknown fields, wrong types and out-of-range values
(numbers must be finite; data values must fit float32, ranges need lo < hi) raise
`ProtocolError` naming the field; so do messages nested deeper than `LIMITS.depth`, refused
before decoding. The server answers {"type": "error", "id", "message"} and keeps serving.
Server -> client: JSON text messages (info, dataset, histogram, fit, probe, progress, download,
events, error, steps: `residency`) and binary frames (`pack_frame`: a 4-byte big-endian header
length, a JSON header, then the images' bytes back to back). A `progress` says how far work got:
of what "refine" (a view's refine, `view` of `views`), "frame" (the frame answering request
`id`, for the busy box), "movie" or "events" ({"stage", "done", "total"}). `info`, sent first on
every socket,
lists the data sets and `choices()`: the registered modes and every other menu, default and
bound the page offers (and whether feature tracking is installed), so the page copies nothing
from here. The schema primitives are in `schema`.
"""

from __future__ import annotations

import json
import re
import struct
from dataclasses import dataclass

from chronocl import modes
from chronocl.core import tf
from chronocl.core.colormaps import PRESETS as COLORMAP_PRESETS
from chronocl.core.colormaps import colormap_stops
from chronocl.core.enhance import ENHANCE_KINDS, Enhance
from chronocl.render.camera import UP_AXES
from chronocl.render.shading import MAX_COEFFICIENT, MAX_SHININESS, MIN_SHININESS
from chronocl.viewer.schema import (
    FLOAT32_MAX,
    Bool,
    Enum,
    Int,
    List,
    Name,
    Nullable,
    Num,
    Obj,
    ProtocolError,
    Range,
    Text,
    Version,
    show,
)


@dataclass(frozen=True)
class Limits:
    """Every limit the viewer's server enforces, in one place (one instance: `LIMITS`): on what
    a client sends, what it may ask for, and what the server holds or tells per client. The
    `info` message gives the page those it checks itself (`choices()["limits"]`). Not tuning:
    bounds against a page flooding or crashing the server, none timed."""

    # A client message's size in bytes (UTF-8), checked before decoding; the socket itself
    # takes at most 4 times this per frame.
    message_bytes: int = 64 * 1024
    # Arrays and objects nested in a message, at most, checked before decoding: the deepest
    # message (update.views[i].data_tf.points[i][j]) nests 6.
    depth: int = 8
    # Views (panels) a client shows at once, and points of a transfer function.
    views: int = 4
    tf_points: int = 64
    # A panel's side in pixels, as the page asks for it.
    panel_min: int = 64
    panel_max: int = 1024
    # Frames of a movie the viewer saves (a window sliding further stops there).
    movie_frames: int = 600
    # Sockets served at once by default (--max-clients), and --max-clients at most.
    clients: int = 32
    clients_most: int = 1000
    # A client's side jobs waiting at once (viewer/side_work.py): more is the page flooding
    # the server.
    side_jobs: int = 16
    # A session file's size, at most (viewer/snapshot.py).
    session_file_bytes: int = 1 << 20
    # Characters of an unexpected exception's message told to the client and the log
    # (viewer/errors.py).
    error_chars: int = 300


LIMITS = Limits()
MOVIES = ("orbit", "play")  # a turn of the camera, or the window slid over the series
MOVIE_FORMATS = {"mp4": "video/mp4", "gif": "image/gif"}
PROBE_THRESHOLD = 0.5  # the probe finds the voxel where a ray's opacity passes this


# --------------------------------------------------------------------------- messages

ORDERS = ("forward", "backward")
PROJECTIONS = ("perspective", "orthographic")
BACKGROUNDS = ("black", "white")
# The time-TF presets the page offers (a TF of explicit points is not edited there).
TIME_COLORS = tuple(c for c in tf.TIME_COLORS if c != "points")
TIME_ALPHAS = tuple(a for a in tf.TIME_ALPHAS if a != "points")
# What the page's menus say for a choice, where its name alone says too little.
LABELS = {
    "rgb": "rgb (old blue → new red)",
    "lightness": "lightness (dark → bright)",
    "inverted-hat": "inverted hat",
    "relative": "relative (to the window)",
    "absolute": "absolute (in the series)",
    "edge": "edge (gradient)",
    "silhouette": "silhouette (view)",
}
# A choice's tooltip, where its short label needs more words.
SUMMARIES = {
    "lightness": "old steps dark, new steps bright: time as lightness under the colour map's hue",
    "relative": "the window spans the colour ramp: its first step old, its last step new",
    "absolute": "a step keeps its colour while the window slides (its place in the whole series)",
}

CAMERA = Obj(
    {
        "azimuth": Num(-1e6, 1e6),
        "elevation": Num(-89.9, 89.9),
        "zoom": Num(0.1, 20.0),
        "fov": Num(5.0, 90.0),
        "projection": Enum(PROJECTIONS),
        "up": Enum(UP_AXES),  # the data axis up on the screen (render/camera.py)
    }
)
WINDOW = Obj(
    {"t0": Int(0, 10**7), "t1": Int(1, 10**7), "stride": Int(1, 10**7)},
    frozenset({"t0", "t1"}),
)
MODE = Enum(modes.names())
DATA_TF = Obj(
    {
        "points": List(List(Num(0.0, 1.0), 5, 5), 1, LIMITS.tf_points),
        "value_range": Nullable(Range(Num(-FLOAT32_MAX, FLOAT32_MAX))),
    },
    frozenset({"points"}),
)
TIME_TF = Obj(
    {
        "color": Enum(TIME_COLORS),
        "focus": Num(0.0, 1.0),
        "falloff": Num(0.01, 10.0),
        "alpha": Enum(TIME_ALPHAS),
        "value": Num(0.0, 1.0),
        "center": Num(0.0, 1.0),
        "width": Num(0.01, 2.0),
        "floor": Num(0.0, 1.0),
        "positions": Enum(tf.TIME_POSITIONS),
    }
)
# A view: its mode and order, and its own window, camera, data TF and time TF, each null (or
# left out) where the view follows the shared one (linked): two periods, two viewpoints or two
# colourings side by side. An own camera or time TF given in part takes the rest from the
# shared one; an own data TF is whole, as the shared one.
VIEW = Obj(
    {
        "mode": MODE,
        "order": Enum(ORDERS),
        "window": Nullable(WINDOW),
        "camera": Nullable(CAMERA),
        "data_tf": Nullable(DATA_TF),
        "time_tf": Nullable(TIME_TF),
    },
    frozenset({"mode"}),
)
ENHANCE = Obj(
    {
        "kind": Enum(ENHANCE_KINDS),
        "k0": Num(0.0, 10.0),
        "k1": Num(0.0, 100.0),
        "k2": Num(0.0, 10.0),
    }
)
CLIP_PLANE = Obj(
    {"normal": List(Num(-1.0, 1.0), 3, 3), "offset": Num(-1.0, 1.0)}, frozenset({"normal"})
)
# Lighting (chronocl/render/shading.py): the Shading's fields, the same bounds.
SHADING = Obj(
    {
        "enabled": Bool(),
        "ambient": Num(0.0, MAX_COEFFICIENT),
        "diffuse": Num(0.0, MAX_COEFFICIENT),
        "specular": Num(0.0, MAX_COEFFICIENT),
        "shininess": Num(MIN_SHININESS, MAX_SHININESS),
    }
)
THRESHOLD = Num(0.0, 0.99)
# The world box (x0, y0, z0, x1, y1, z1) the camera frames (render/framing.py; the box's
# longest side is 1, centred on the origin).
FOCUS = List(Num(-1.0, 1.0), 6, 6)
ID = Int(0, 2**53)
SIZE = List(Int(LIMITS.panel_min, LIMITS.panel_max), 2, 2)

# A snapshot: the saved viewer state (the viewer's Save session, the URL fragment, `chronocl
# render --state`; viewer/snapshot.py): the state fields of an update message plus the data set
# and the format's version. Enhancement and lighting are shared by the views; a view's own
# window, camera and TFs are in `views`.
# The file format keeps its name ("session"), so files saved before still load.
SESSION_VERSION = 1
SESSION_KEY = "chronocl_session"
# What a frame depends on, as the update message and a snapshot both give it.
VIEW_FIELDS = {
    "window": WINDOW,
    "views": List(VIEW, 1, LIMITS.views),
    "camera": CAMERA,
    "data_tf": DATA_TF,
    "time_tf": TIME_TF,
    "enhance": ENHANCE,
    "threshold": THRESHOLD,
    "clip": Nullable(CLIP_PLANE),
    "size": SIZE,
    "background": Enum(BACKGROUNDS),
    "outline": Bool(),
}
SNAPSHOT = Obj(
    {
        SESSION_KEY: Version(SESSION_VERSION, "session files of"),
        "dataset": Obj(
            {"name": Text(200), "path": Text(4096), "shape": List(Int(1, 2**31), 4, 4)},
            frozenset({"name"}),
        ),
        **VIEW_FIELDS,
        "shading": Nullable(SHADING),
        "focus": Nullable(FOCUS),
    },
    frozenset({SESSION_KEY, "dataset", "window", "views", "camera", "data_tf", "time_tf"}),
)

UNIT_RANGE, NEEDS_RANGE = Range(Num(0.0, 1.0)), frozenset({"range"})  # histogram
# The events panel (chronocl/viewer/events_panel.py): what a step shows (the data TF's opacity
# above `opacity`, or values at least `value`) and how its voxels connect.
EVENT_ACTIONS = ("find", "markers", "track", "clear")
EVENT_BY = ("opacity", "value")
CONNECTIVITIES = (6, 18, 26)
EVENT_OPACITY = Num(0.0, 0.99)
MESSAGES: dict[str, Obj] = {
    "open": Obj(
        {"type": Enum(("open",)), "id": ID, "dataset": Name(), "fit": Bool()},
        frozenset({"dataset"}),
    ),
    "update": Obj(
        {
            "type": Enum(("update",)),
            "id": ID,
            **VIEW_FIELDS,
            "quality": Enum(("preview", "full")),
            "shading": SHADING,
            "refocus": Bool(),  # frame the visible region again (the camera reset)
            "focus": FOCUS,  # frame this world box (a snapshot's, an undone state's)
        }
    ),
    "probe": Obj(
        {
            "type": Enum(("probe",)),
            "id": ID,
            "view": Int(0, LIMITS.views - 1),
            "x": Num(0.0, 1.0),
            "y": Num(0.0, 1.0),
            "x2": Num(0.0, 1.0),
            "y2": Num(0.0, 1.0),
            # or pinned on a slice ("z=40") at (u, v) of its voxel grid, as a read-out is
            "slice": Text(40),
            "u": Num(0.0, 1.0),
            "v": Num(0.0, 1.0),
        },
    ),
    # one plane of a view's chronovolume ("z=40"), and the read-out at (u, v) of its voxel grid
    "slice": Obj(
        {
            "type": Enum(("slice",)),
            "id": ID,
            "view": Int(0, LIMITS.views - 1),
            "slice": Text(40),
            "u": Num(0.0, 1.0),
            "v": Num(0.0, 1.0),
            "picture": Bool(),  # false: the read-out at (u, v) alone (a pointer moving)
            "size": SIZE,  # the room for the picture on the page (default: the view's size)
        },
        frozenset({"slice"}),
    ),
    # `of`: the values (default), or the changes between consecutive steps (a mode whose data
    # TF maps them: `Mode.data_axis`), scaled to `value_range` (the TF's; none: the series')
    "histogram": Obj(
        {
            "type": Enum(("histogram",)),
            "id": ID,
            "range": UNIT_RANGE,
            "of": Enum(("value", "change")),
            "value_range": Nullable(Range(Num(-FLOAT32_MAX, FLOAT32_MAX))),
            "view": Int(0, LIMITS.views - 1),  # whose window it counts (default 0)
        },
        NEEDS_RANGE,
    ),
    "fit": Obj({"type": Enum(("fit",)), "id": ID, "view": Int(0, LIMITS.views - 1), "mode": MODE}),
    "save": Obj(
        {
            "type": Enum(("save",)),
            "id": ID,
            "what": Enum(("image", "chronovolume", "movie", "session")),
            "view": Int(0, LIMITS.views - 1),
            "movie": Enum(MOVIES),
            "format": Enum(tuple(MOVIE_FORMATS)),
            "frames": Int(2, 360),
            "fps": Int(1, 60),
            "columns": Int(1, LIMITS.views),  # panels per row, as on screen (image, movie)
        },
        frozenset({"what"}),
    ),
    "load": Obj({"type": Enum(("load",)), "id": ID, "session": SNAPSHOT}, frozenset({"session"})),
    "cancel": Obj({"type": Enum(("cancel",)), "id": ID}),
    "events": Obj(
        {
            "type": Enum(("events",)),
            "id": ID,
            "action": Enum(EVENT_ACTIONS),
            "view": Int(0, LIMITS.views - 1),
            "by": Enum(EVENT_BY),
            "opacity": EVENT_OPACITY,
            "value": Num(-FLOAT32_MAX, FLOAT32_MAX),
            "connectivity": Int(6, 26),
            "show": Bool(),
            "track": Nullable(Int(0, 2**31)),
            "find": ID,  # track: the id of the find whose list it was chosen in
        },
        frozenset({"action"}),
    ),
}


def _check_events(msg: dict) -> dict:
    """An `events` message's fields that must go together (after its schema)."""
    action = msg["action"]
    takes = {"find": set(), "markers": {"show"}, "track": {"track"}, "clear": set()}[action]
    if action != "find":
        optional = {"find"} if action == "track" else set()
        extra = sorted(set(msg) - {"type", "id", "action"} - takes - optional)
        if extra:
            raise ProtocolError(f"events.{extra[0]} does not go with {action}")
        missing = sorted(takes - set(msg))
        if missing:
            raise ProtocolError(f"events.{missing[0]} is missing: {action} needs it")
        return msg
    if "track" in msg or "find" in msg:
        field = "track" if "track" in msg else "find"
        raise ProtocolError(f"events.{field} does not go with find; choose a track with track")
    if msg.get("connectivity", 26) not in CONNECTIVITIES:
        raise ProtocolError(
            f"events.connectivity is {msg['connectivity']}; choose 6, 18 or 26 (voxels sharing "
            "a face, an edge or a corner)"
        )
    by = msg.get("by", "opacity")
    if by == "value" and "value" not in msg:
        raise ProtocolError("events.value is missing: by value needs the value a voxel reaches")
    other = "value" if by == "opacity" else "opacity"
    if other in msg:
        raise ProtocolError(f"events.{other} does not go with by {by}; send {by} instead")
    return msg


def _menu(names: tuple[str, ...]) -> list[dict]:
    return [
        {
            "name": n,
            "label": LABELS.get(n, n),
            **({"summary": SUMMARIES[n]} if n in SUMMARIES else {}),
        }
        for n in names
    ]


def _ranges(obj: Obj) -> dict:
    return {k: [f.lo, f.hi] for k, f in obj.fields.items() if isinstance(f, Num)}


def choices() -> dict:
    """What the page may choose from and the bounds it must keep, for the `info` message.

    The modes are the registry's (name, one-line summary, whether the mode records the step
    that supplied a voxel), in its order; nothing in the page names a mode. Enhancement kinds
    come with their default parameters; `ranges` are the bounds the schemas above enforce.
    """
    return {
        "modes": [
            {
                "name": n,
                "summary": modes.get(n).summary,
                "has_t_index": modes.get(n).has_t_index,
                "data_axis": modes.get(n).data_axis,  # what its data TF maps: value or change
            }
            for n in modes.names()
        ],
        "orders": list(ORDERS),
        "projections": list(PROJECTIONS),
        "up_axes": list(UP_AXES),
        "backgrounds": list(BACKGROUNDS),
        "time_colors": _menu(TIME_COLORS),
        "time_alphas": [  # with the parameters each shape reads
            item | {"params": [k for k in tf.TimeAlpha(item["name"]).to_dict() if k != "shape"]}
            for item in _menu(TIME_ALPHAS)
        ],
        "positions": _menu(tf.TIME_POSITIONS),
        "colormaps": {name: colormap_stops(name) for name in COLORMAP_PRESETS},
        "data_tf_default": [list(p) for p in tf.DEFAULT_DATA_POINTS],
        "enhance": [
            item | {"k": [e.k0, e.k1, e.k2]}
            for item, e in zip(_menu(ENHANCE_KINDS), map(Enhance, ENHANCE_KINDS), strict=True)
        ],
        "ranges": {
            "camera": _ranges(CAMERA),
            "time_tf": _ranges(TIME_TF),
            "enhance": _ranges(ENHANCE),
            "clip": _ranges(CLIP_PLANE),
            "shading": _ranges(SHADING),
            "threshold": [THRESHOLD.lo, THRESHOLD.hi],
        },
        "events": events_choices(),
        "limits": {
            "max_views": LIMITS.views,
            "max_message_bytes": LIMITS.message_bytes,
            "max_tf_points": LIMITS.tf_points,
            "min_panel": LIMITS.panel_min,
            "max_panel": LIMITS.panel_max,
            "probe_threshold": PROBE_THRESHOLD,
        },
    }


def events_choices() -> dict:
    """Whether feature tracking is installed (the ``events`` extra; looked up, not imported),
    the line that installs it, and the panel's choices and default."""
    from importlib.util import find_spec

    from chronocl.events.extra import INSTALL, PACKAGES

    return {
        "available": all(find_spec(module) is not None for module in PACKAGES),
        "install": INSTALL,
        "by": list(EVENT_BY),
        "connectivity": list(CONNECTIVITIES),
        "opacity": 0.1,
        "opacity_range": [EVENT_OPACITY.lo, EVENT_OPACITY.hi],
    }


def _reject_constant(name: str) -> float:
    raise ProtocolError(f"{name} is not allowed in a message; send finite numbers")


_STRINGS = re.compile(r'"(?:[^"\\]|\\.)*"', re.S)
_BRACKETS = re.compile(r"[\[\]{}]")


def too_deep(text: str, limit: int = LIMITS.depth) -> bool:
    """Whether the JSON text nests arrays and objects deeper than `limit` (strings skipped;
    a cheap scan before decoding, which recurses once per level)."""
    depth = 0
    for m in _BRACKETS.finditer(_STRINGS.sub("", text)):
        if m.group() in "[{":
            depth += 1
            if depth > limit:
                return True
        else:
            depth -= 1
    return False


def decode_json(text: str) -> object:
    """json.loads without NaN/Infinity and without deep nesting (ProtocolError, ValueError)."""
    if too_deep(text):
        raise ProtocolError(
            f"message nests arrays or objects more than {LIMITS.depth} deep; send a flat message"
        )
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except RecursionError:  # the scan above should have caught it
        raise ProtocolError("message nests too deep; send a flat message") from None


def request_id(text: object) -> int | None:
    """The `id` of a message, if it has a usable one (for error replies to bad messages)."""
    if not isinstance(text, str) or len(text) > LIMITS.message_bytes or too_deep(text):
        return None
    try:  # NaN and Infinity elsewhere in the message do not hide its id
        msg = json.loads(text, parse_constant=lambda name: None)
    except (ValueError, RecursionError):
        return None
    rid = msg.get("id") if isinstance(msg, dict) else None
    return rid if isinstance(rid, int) and not isinstance(rid, bool) and 0 <= rid <= 2**53 else None


def parse_message(text: object) -> dict:
    """Decode and validate one client message; raises ProtocolError naming what is wrong."""
    if isinstance(text, bytes | bytearray):
        raise ProtocolError("binary messages are not accepted; send JSON text")
    if not isinstance(text, str):
        raise ProtocolError("empty message; send a JSON object")
    most = LIMITS.message_bytes
    if len(text) > most:  # characters; a cheap bound before decoding
        raise ProtocolError(f"message of {len(text)} characters is over the limit of {most}")
    if len(text.encode()) > most:
        raise ProtocolError(f"message is over the limit of {most} bytes")
    try:
        msg = decode_json(text)
    except ProtocolError:
        raise
    except ValueError as exc:
        raise ProtocolError(f"message is not valid JSON ({exc})") from None
    if not isinstance(msg, dict):
        raise ProtocolError("message must be a JSON object with a 'type'")
    kind = msg.get("type")
    if not isinstance(kind, str) or kind not in MESSAGES:
        raise ProtocolError(
            f"unknown message type {show(kind)}; choose one of {', '.join(MESSAGES)}"
        )
    checked = MESSAGES[kind].check(msg, kind)
    return _check_events(checked) if kind == "events" else checked


def pack_frame(header: dict, images: list[bytes]) -> bytes:
    """A binary frame: header length (uint32, big-endian), JSON header, image bytes in order
    (the header lists each image's byte length under `views[i].bytes`)."""
    head = json.dumps(header, separators=(",", ":")).encode()
    return b"".join([struct.pack(">I", len(head)), head, *images])


def unpack_frame(data: bytes) -> tuple[dict, list[bytes]]:
    """The inverse of `pack_frame` (for tests and the benchmark)."""
    (n,) = struct.unpack(">I", data[:4])
    header = json.loads(data[4 : 4 + n])
    images, at = [], 4 + n
    for view in header["views"]:
        images.append(data[at : at + view["bytes"]])
        at += view["bytes"]
    return header, images
