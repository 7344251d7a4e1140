"""The viewer's slice of a view: the picture `chronocl render --slice` draws of the view's shown
chronovolume (`chronocl.render.slices`), where its voxel grid lies in it, and the read-out at a
point of the slice.

A `slice` request names the view, the slice ("z=40"), the picture's `size` (the page's panel;
the view's by default) and optionally a point (`u`, `v` in [0, 1] of the slice's voxel grid,
across from the left and down from the top, as a page's pointer over the grid `box` gives
them). The reply carries the picture as a PNG data URL, its
`layout` (in pixels of the picture) and `box` (where the grid lies in each of the layout's
`pictures`, in pixels from that picture's corner), the grid's rows and columns, and at the point
the voxel, its position in data units, the step that won there, its time and the series' raw
value at that voxel and step.

The render thread answers it between frames (`tasks._do_task`), from the view's chronovolume
at full resolution, as it answers a probe. The page's slice panel (`static/slice.js`) sends it;
`t_index` in the reply says whether the view's mode keeps a winning step at all, `outline`
where the plane cuts the volume's box on the view's panel (`clip_outline`, as the clip plane's).
"""

from __future__ import annotations

import base64
import dataclasses

from chronocl.core.errors import InvalidParameterError
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.slices import (
    Slice,
    grid_shape,
    parse_slice,
    slice_picture,
    slice_value,
    slice_voxel,
)
from chronocl.viewer.clip_outline import clip_outline
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.protocol import LIMITS
from chronocl.viewer.view_state import ViewState


def slice_clip(sl: Slice, cv: Chronovolume) -> tuple[float, float, float, float]:
    """The slice's plane as a clip plane (nx, ny, nz, offset): through its voxels' centres."""
    n = dict(zip("xyz", cv.shape[::-1], strict=True))[sl.axis]
    normal = tuple(1.0 if a == sl.axis else 0.0 for a in "xyz")
    return (*normal, (2 * sl.index + 1) / n - 1)  # type: ignore[return-value]


def panel_size(room, view_size, pictures: int) -> tuple[int, int]:
    """Each of the slice's `pictures` (the colours, and the step map where the mode keeps a
    t_index) drawn side by side in `room` (W, H), the page's panel: an equal share of its width
    at the view's aspect, no taller than three quarters of its height (the captions and legend
    bands take the rest); the view's size where the page names no room."""
    if room is None:
        return tuple(view_size)  # type: ignore[return-value]
    w = max(LIMITS.panel_min, room[0] // pictures)
    h = round(w * view_size[1] / view_size[0])
    return w, max(LIMITS.panel_min, min(h, LIMITS.panel_max, room[1] * 3 // 4))


def point_voxel(msg: dict, sl: Slice, shape) -> tuple[int, int, int]:
    """The voxel (x, y, z) under the point (`u`, `v`) of `msg` on slice `sl`'s voxel grid (a
    read-out's, or a probe pinned on the slice)."""
    u, v = msg.get("u"), msg.get("v")
    if not all(isinstance(f, int | float) and not isinstance(f, bool) for f in (u, v)) or not (
        0 <= u <= 1 and 0 <= v <= 1  # type: ignore[operator]
    ):
        raise InvalidParameterError(f"slice point u={u!r}, v={v!r} must be two numbers in [0, 1]")
    rows, cols = grid_shape(sl, shape)
    col = min(cols - 1, int(u * cols))  # type: ignore[operator]
    row = min(rows - 1, int(v * rows))  # type: ignore[operator]
    return slice_voxel(sl, shape, col, row)


def slice_reply(msg: dict, view: int, state: ViewState, cv: Chronovolume, ds: Dataset) -> dict:
    """The `slice` reply to `msg` for the shown `view` of `state` (its chronovolume `cv`, of
    data set `ds`): the slice picture at the size asked for (else the view's) and background,
    where its grid lies, and with a point (`u`, `v`) the read-out there (None without one).
    With `picture` false (a pointer moving over the picture the page has) only the read-out:
    no picture is drawn."""
    sl = parse_slice(msg.get("slice"), cv.shape)
    reply = {
        "type": "slice",
        "id": msg.get("id"),
        "view": view,
        "slice": str(sl),
        "t_index": cv.t_index is not None,  # the mode keeps the step that won each voxel
        "readout": None,
    }
    if msg.get("picture", True):
        size = panel_size(msg.get("size"), state.size, 1 if cv.t_index is None else 2)
        pic = slice_picture(cv, sl, size, state.background, name=ds.name)
        rows, cols = pic.grid
        reply |= {
            "png": "data:image/png;base64," + base64.b64encode(pic.image.png_bytes()).decode(),
            "size": list(pic.image.size),
            "layout": dataclasses.asdict(pic.layout),
            "box": list(pic.box),
            "grid": {"rows": rows, "cols": cols, "across": sl.across, "up": sl.up},
            # the plane's outline on the view's panel under its camera now, as the clip plane's
            "outline": clip_outline(cv, state.panel_camera(view), state.size, slice_clip(sl, cv)),
        }
    if "u" not in msg and "v" not in msg:
        return reply
    x, y, z = point_voxel(msg, sl, cv.shape)
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
