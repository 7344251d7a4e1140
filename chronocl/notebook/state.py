"""The widget's synced attributes in the viewer protocol's terms: an attribute's value as the
fields of an `update` message (what setting it sends), and the attributes read back from the
state the worker holds (`view_state.describe_state`), whoever changed it: code or the page.

    window   (t0, t1, stride)      set (t0, t1) or (t0, t1, stride); t1 exclusive
    mode     the first view's mode (set: that view's mode; the others keep theirs)
    views    [{"mode", "order", "window", "camera", "data_tf", "time_tf"}, ...]: each view's own
             window, camera and TFs, None where it follows the shared one (linked); set a list
             of dicts (an own camera or time TF in part: the rest the shared one's) or of modes
    data_tf  {"points": [[u, r, g, b, a], ...], "value_range": [lo, hi]} (no range: the series')
    time_tf  {"color", "alpha", ...}; set any subset, the rest kept
    camera   {"azimuth", "elevation", "zoom", "fov", "projection", "up"}; set any subset
"""

from __future__ import annotations

from collections.abc import Sequence

from chronocl.core.errors import InvalidParameterError

SYNCED = ("window", "mode", "views", "data_tf", "time_tf", "camera")


def from_state(described: dict) -> dict:
    """The attributes' values for a state described in the protocol's terms."""
    w = described["window"]
    return {
        "window": (w["t0"], w["t1"], w["stride"]),
        "mode": described["views"][0]["mode"],
        "views": [dict(v) for v in described["views"]],
        "data_tf": dict(described["data_tf"]),
        "time_tf": dict(described["time_tf"]),
        "camera": dict(described["camera"]),
    }


def to_fields(name: str, value: object, described: dict) -> dict:
    """The update message's fields that set attribute `name` to `value`, given the state now
    (`described`); InvalidParameterError for a value of the wrong shape (the protocol's
    schemas check the rest)."""
    if name == "window":
        return {"window": _window(value, described["window"]["stride"])}
    if name == "mode":
        if not isinstance(value, str):
            raise InvalidParameterError(f"mode must be a mode's name, not {value!r}")
        views = [dict(v) for v in described["views"]]
        views[0]["mode"] = value
        return {"views": views}
    if name == "views":
        return {"views": _views(value)}
    if name in ("data_tf", "time_tf", "camera"):
        if not isinstance(value, dict):
            raise InvalidParameterError(f"{name} must be a dict, not {type(value).__name__}")
        return {name: dict(value)}
    raise InvalidParameterError(f"{name} is not a synced attribute; choose one of {SYNCED}")


def _window(value: object, stride: int) -> dict:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) not in (2, 3):
        raise InvalidParameterError(
            f"window must be (t0, t1) or (t0, t1, stride) with t1 exclusive, not {value!r}"
        )
    t0, t1, *rest = value
    return {"t0": t0, "t1": t1, "stride": rest[0] if rest else stride}


def _views(value: object) -> list[dict]:
    if not isinstance(value, Sequence) or isinstance(value, str) or not value:
        raise InvalidParameterError(
            "views must be a list of modes or of {'mode', 'order', 'window', 'camera', "
            f"'data_tf', 'time_tf'}}, not {value!r}"
        )
    views = []
    for v in value:
        if isinstance(v, str):
            views.append({"mode": v})
        elif isinstance(v, dict):
            views.append(dict(v))
        else:
            raise InvalidParameterError(f"a view must be a mode's name or a dict, not {v!r}")
    return views
