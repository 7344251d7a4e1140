"""The viewer's slice of a view: the picture `chronocl render --slice` draws of the view's shown
chronovolume (`chronocl.render.slices`), where its voxel grid lies in it, and the read-out at a
point of the slice.

A `slice` request names the view, the slice ("z=40") and optionally a point (`u`, `v` in
[0, 1] of the slice's voxel grid, across from the left and down from the top, as a page's
pointer over the grid `box` gives them). The reply carries the picture as a PNG data URL, its
`layout` and `box` (in pixels of the picture), the grid's rows and columns, and at the point
the voxel, its position in data units, the step that won there, its time and the series' raw
value at that voxel and step.

The render thread answers it between frames (`tasks._do_task`), from the view's chronovolume
at full resolution, as it answers a probe. The page has no slice panel yet: a script or the
notebook's comm sends the request.
"""

from __future__ import annotations

import base64
import dataclasses

from chronocl.core.errors import InvalidParameterError
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.slices import slice_picture, slice_value, slice_voxel
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.view_state import ViewState


def slice_reply(msg: dict, view: int, state: ViewState, cv: Chronovolume, ds: Dataset) -> dict:
    """The `slice` reply to `msg` for the shown `view` of `state` (its chronovolume `cv`, of
    data set `ds`): the slice picture at the view's size and background, where its grid lies,
    and with a point (`u`, `v`) the read-out there (None without one)."""
    pic = slice_picture(cv, msg.get("slice"), state.size, state.background, name=ds.name)
    rows, cols = pic.grid
    reply = {
        "type": "slice",
        "id": msg.get("id"),
        "view": view,
        "slice": str(pic.slice),
        "png": "data:image/png;base64," + base64.b64encode(pic.image.png_bytes()).decode(),
        "size": list(pic.image.size),
        "layout": dataclasses.asdict(pic.layout),
        "box": list(pic.box),
        "grid": {"rows": rows, "cols": cols, "across": pic.slice.across, "up": pic.slice.up},
        "readout": None,
    }
    if "u" not in msg and "v" not in msg:
        return reply
    u, v = msg.get("u"), msg.get("v")
    if not all(isinstance(f, int | float) and not isinstance(f, bool) for f in (u, v)) or not (
        0 <= u <= 1 and 0 <= v <= 1  # type: ignore[operator]
    ):
        raise InvalidParameterError(f"slice point u={u!r}, v={v!r} must be two numbers in [0, 1]")
    col = min(cols - 1, int(u * cols))  # type: ignore[operator]
    row = min(rows - 1, int(v * rows))  # type: ignore[operator]
    x, y, z = slice_voxel(pic.slice, cv.shape, col, row)
    got = slice_value(cv, ds.series, x, y, z)
    reply["readout"] = {
        "voxel": {"x": x, "y": y, "z": z},
        "position": dict(zip("xyz", got.position, strict=True)),
        "step": got.step,
        "time": got.time_text,
        "value": got.value,
        "text": got.describe(),
    }
    return reply
