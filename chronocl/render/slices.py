"""Slices through a chronovolume: one plane of voxels across an axis (`z=40`), drawn as its
colours composited over the background (as the raycaster composites: rgb + (1 - a) * bg, the
RGBA being premultiplied) and, in modes with a t_index, beside it a map of the step that won
each voxel through the time TF's colours with its own time legend (-1, nothing won, or a
transparent winner: the background). The read-out (`slice_value`) gives, at a voxel, the
winning step, its time, the series' raw value there at that step and the voxel's position in
data units.

Orientation: a z slice shows x across and y up, a y slice x across and z up, an x slice y
across and z up (the second axis increases upwards, as in ParaView). Each voxel is drawn
`spacing` wide, the picture scaled to fit its panel with the data's aspect ratio kept and
centred in it (`fit_box`; nearest neighbour, so every pixel is one voxel's colour).

    image = chronocl.render_slice(cv, "z=40")        # or chronocl render --slice z=40
    chronocl.slice_value(cv, series, x=3, y=4, z=40)  # step, time, value, position
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.core.time_labels import check_prefer, display_labels
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.image import Image
from chronocl.render.legends import time_legend
from chronocl.render.panels import Layout, compose, label_font
from chronocl.render.raycaster import check_size
from chronocl.render.views import describe, parse_color, title_text

if TYPE_CHECKING:
    from chronocl.data.timeseries import TimeSeries

AXES = "xyz"
# The axes a slice across each axis shows: (across, up).
PLANE = {"z": ("x", "y"), "y": ("x", "z"), "x": ("y", "z")}
_SPEC = re.compile(r"^\s*([A-Za-z]+)\s*=\s*([+-]?\d+)\s*$")


@dataclass(frozen=True)
class Slice:
    """The plane of voxels whose `axis` ("x", "y" or "z") index is `index`."""

    axis: str
    index: int

    def __str__(self) -> str:
        return f"{self.axis}={self.index}"

    @property
    def across(self) -> str:
        """The axis that runs across the picture."""
        return PLANE[self.axis][0]

    @property
    def up(self) -> str:
        """The axis that runs up the picture."""
        return PLANE[self.axis][1]


def parse_slice(spec: object, shape_zyx: tuple[int, int, int] | None = None) -> Slice:
    """A slice from "z=40" (or ("z", 40), or a Slice); with the volume's (Z, Y, X) shape, its
    index checked inside it. One line naming what is wrong otherwise."""
    m = _SPEC.match(spec) if isinstance(spec, str) else None
    if isinstance(spec, Slice):
        axis, index = spec.axis, spec.index
    elif m and m.group(1).lower() in AXES:
        axis, index = m.group(1).lower(), int(m.group(2))
    elif isinstance(spec, tuple | list) and len(spec) == 2 and spec[0] in tuple(AXES):
        axis, index = spec
        if isinstance(index, bool) or not isinstance(index, int | np.integer):
            raise InvalidParameterError(f"slice index {index!r} must be a whole voxel index")
        index = int(index)
    else:
        raise InvalidParameterError(
            f"slice {spec!r} must be x=N, y=N or z=N (N a voxel index), e.g. z=40"
        )
    if shape_zyx is not None:
        n = shape_zyx[2 - AXES.index(axis)]
        if not 0 <= index < n:
            raise InvalidParameterError(
                f"slice {axis}={index} is outside the volume: {axis} runs 0..{n - 1}"
            )
    return Slice(axis, index)


def _plane(volume: np.ndarray, sl: Slice) -> np.ndarray:
    """The (rows, cols, ...) plane of a (Z, Y, X, ...) array, top row the highest `up` index."""
    if sl.axis == "z":
        plane = volume[sl.index]  # (Y, X)
    elif sl.axis == "y":
        plane = volume[:, sl.index]  # (Z, X)
    else:
        plane = volume[:, :, sl.index]  # (Z, Y)
    return plane[::-1]


def grid_shape(sl: Slice, shape_zyx: tuple[int, int, int]) -> tuple[int, int]:
    """(rows, cols) of the slice's voxel grid in a volume of `shape_zyx` (as `_plane` gives)."""
    nz, ny, nx = shape_zyx
    return {"z": (ny, nx), "y": (nz, nx), "x": (nz, ny)}[sl.axis]


def slice_voxel(sl: Slice, shape_zyx: tuple[int, int, int], col: int, row: int):
    """The voxel (x, y, z) at column `col`, row `row` (0: top) of the slice's voxel grid."""
    nz, ny, nx = shape_zyx
    n_up = {"x": nx, "y": ny, "z": nz}[sl.up]
    v = {sl.axis: sl.index, sl.across: int(col), sl.up: n_up - 1 - int(row)}
    return v["x"], v["y"], v["z"]


def composite(rgba: np.ndarray, background) -> np.ndarray:
    """Premultiplied RGBA (..., 4) over `background` as uint8 RGB: rgb + (1 - a) * bg, as the
    raycaster composites a ray."""
    bg = np.asarray(parse_color(background), dtype=np.float32)
    rgba = np.asarray(rgba, dtype=np.float32)
    rgb = rgba[..., :3] + (1.0 - rgba[..., 3:4]) * bg
    return np.round(np.clip(rgb, 0.0, 1.0) * 255).astype(np.uint8)


def _plane_rgba(cv: Chronovolume, sl: Slice) -> np.ndarray:
    """The slice's RGBA as float32 (a display chronovolume's RGBA8 / 255, as `float_rgba`),
    the plane taken first: converting the whole volume took 2 GiB and 0.1 s a picture at 512^3."""
    plane = _plane(cv.rgba, sl)
    if plane.dtype == np.uint8:
        return plane.astype(np.float32) / np.float32(255)
    return np.asarray(plane, dtype=np.float32)


def slice_colours(cv: Chronovolume, sl: object, background: object = "black") -> np.ndarray:
    """The slice's colours, one pixel per voxel (rows, cols, 3) uint8, over `background`."""
    sl = parse_slice(sl, cv.shape)
    return composite(_plane_rgba(cv, sl), background)


def slice_steps(cv: Chronovolume, sl: object) -> np.ndarray | None:
    """The step that won each voxel of the slice (rows, cols) int32, -1 where none did; None
    for a mode without a t_index."""
    if cv.t_index is None:
        return None
    sl = parse_slice(sl, cv.shape)
    return np.ascontiguousarray(_plane(np.asarray(cv.t_index), sl), dtype=np.int32)


def step_colours(cv: Chronovolume) -> dict[int, tuple[int, int, int]]:
    """Each selected step's colour as the time legend draws it: the time TF's rgb at the step's
    position, darkened where it is nearly transparent (rgb * max(alpha, 0.25))."""
    spec = cv.spec
    steps = cv.steps
    positions = spec.time_tf.positions_of(steps, cv.metadata["selection"]["n_steps"])
    rgb, alpha = spec.time_tf.evaluate(np.asarray(positions, dtype=np.float64))
    shown = np.clip(rgb * np.maximum(alpha, 0.25)[:, None], 0, 1)
    return {
        int(s): tuple(round(float(c) * 255) for c in shown[k])  # type: ignore[misc]
        for k, s in enumerate(steps)
    }


def step_map(cv: Chronovolume, sl: object, background: object = "black") -> np.ndarray | None:
    """The slice's winning steps in their time colours (rows, cols, 3) uint8, the background
    where no step won or where the winner is transparent (in max and min, empty space is won
    by the window's first step, a tie, and drew a block of its colour around the data); None
    for a mode without a t_index."""
    sl = parse_slice(sl, cv.shape)
    won = slice_steps(cv, sl)
    if won is None:
        return None
    bg = tuple(round(c * 255) for c in parse_color(background))
    out = np.empty((*won.shape, 3), dtype=np.uint8)
    out[...] = bg
    seen = _plane(cv.rgba[..., 3], sl) > 0
    for step, colour in step_colours(cv).items():
        out[(won == step) & seen] = colour
    return out


def plane_spacing(cv: Chronovolume, sl: Slice) -> tuple[float, float]:
    """(across, up): the width and height of one voxel of the slice in data units."""
    sp = dict(zip(AXES, cv.spacing, strict=True))
    return float(sp[sl.across]), float(sp[sl.up])


def fit_box(
    grid: tuple[int, int], spacing: tuple[float, float], size: tuple[int, int]
) -> tuple[int, int, int, int]:
    """Where a (rows, cols) voxel grid, each voxel `spacing` (across, up) in data units, lies
    in a panel of `size` (w, h): (x, y, width, height) in pixels, its aspect ratio kept and
    centred."""
    rows, cols = grid
    w, h = size
    width_units, height_units = cols * spacing[0], rows * spacing[1]
    scale = min(w / width_units, h / height_units)
    pw = min(w, max(1, round(width_units * scale)))
    ph = min(h, max(1, round(height_units * scale)))
    return (w - pw) // 2, (h - ph) // 2, pw, ph


def fitted(grid_rgb: np.ndarray, box, size: tuple[int, int], background: object) -> np.ndarray:
    """A panel of `size` over the background with the voxel grid drawn in `box` by nearest
    neighbour: the pixel at (i, j) of the box shows voxel (i * rows // height, j * cols //
    width)."""
    rows, cols = grid_rgb.shape[:2]
    x0, y0, pw, ph = box
    w, h = size
    panel = np.empty((h, w, 3), dtype=np.uint8)
    panel[...] = tuple(round(c * 255) for c in parse_color(background))
    r = (np.arange(ph) * rows) // ph
    c = (np.arange(pw) * cols) // pw
    panel[y0 : y0 + ph, x0 : x0 + pw] = grid_rgb[r[:, None], c[None, :]]
    return panel


def render_slice(
    chronovolume: Chronovolume,
    slice: object,
    size: tuple[int, int] = (512, 512),
    *,
    background: object = "black",
    time_labels: str = "labels",
    name: str | None = None,
) -> Image:
    """The slice `slice` ("z=40": a voxel index along x, y or z) of a chronovolume as an Image:
    its colours composited over the background in a panel of `size` with the chronovolume's
    legend, and, where the mode has a t_index, beside it the map of the step that won each
    voxel in the time TF's colours with the time legend (the background where none won). The
    data's spacing keeps the aspect ratio. A title band names the data set (`name`, by default
    the name of the store the chronovolume came from) and the window, as the viewer's saved
    pictures do."""
    return slice_picture(chronovolume, slice, size, background, time_labels, name).image


@dataclass(frozen=True)
class SlicePicture:
    """A slice's picture and where its parts lie: `layout` (the title band, each panel's
    caption, picture and legend), `box` (x, y, width, height) where the voxel grid lies in
    each panel's picture, `grid` its (rows, cols) of voxels, and the `slice`."""

    image: Image
    layout: Layout
    box: tuple[int, int, int, int]
    grid: tuple[int, int]
    slice: Slice


def slice_picture(
    cv: Chronovolume,
    spec: object,
    size: tuple[int, int] = (512, 512),
    background: object = "black",
    time_labels: str = "labels",
    name: str | None = None,
) -> SlicePicture:
    """`render_slice`'s picture with where its parts lie (a page maps a pointer to a voxel:
    `slice_voxel`)."""
    sl = parse_slice(spec, cv.shape)
    w, h = check_size(size)
    bg = parse_color(background)
    check_prefer(time_labels)
    colours = slice_colours(cv, sl, bg)
    box = fit_box(colours.shape[:2], plane_spacing(cv, sl), (w, h))
    panels = [fitted(colours, box, (w, h), bg)]
    where = f"slice {sl} of 0..{cv.dims[AXES.index(sl.axis)] - 1}"
    labels = [f"{describe(cv, time_labels)}; {where}"]
    steps = step_map(cv, sl, bg)
    if steps is not None:
        panels.append(fitted(steps, box, (w, h), bg))
        labels.append(f"step that won ({cv.spec.mode}); {where}")
    if name is None:  # the store's name where it has one, else what the data set calls itself
        source = str(cv.metadata.get("store") or cv.metadata.get("dataset") or "")
        name = os.path.basename(source.rstrip("/")) or None
    title = None if name is None else title_text(name, [cv], time_labels)
    array, layout = compose(panels, labels, [cv] * len(panels), None, bg, time_labels, title)
    if steps is not None:  # the step map's own legend: the time colours alone
        array = _time_legend_only(array, layout.legends[1], cv, bg, w, h, time_labels)
    text = {"Description": "\n".join(labels), "Software": "chronocl"}
    if title is not None:
        text["Title"] = title
    return SlicePicture(Image(array, text), layout, box, colours.shape[:2], sl)


def _time_legend_only(array, legend_box, cv, bg, w, h, time_labels) -> np.ndarray:
    """`array` with the legend band `legend_box` redrawn as the time legend alone (no data
    colour bar: the step map's colours are the time TF's)."""
    from PIL import Image as PILImage
    from PIL import ImageDraw

    canvas = PILImage.fromarray(array)
    draw = ImageDraw.Draw(canvas)
    x, y, bw, bh = legend_box
    draw.rectangle((x, y, x + bw - 1, y + bh - 1), fill=tuple(round(c * 255) for c in bg))
    text_rgb = (20, 20, 20) if sum(bg) > 1.5 else (235, 235, 235)
    font = label_font(max(11, min(w, h) // 26))
    band_h = min(bh - 8, max(36, h // 8) - 8)  # one legend's height, as compose draws it
    time_legend(draw, cv, (x + 8, y + 4, bw - 16, band_h), font, text_rgb, time_labels)
    return np.asarray(canvas)


@dataclass(frozen=True)
class SliceValue:
    """What a slice reads at a voxel: the step that won it (None: none did, or the mode keeps
    no t_index), that step's time label (raw) and its display text, the series' raw value at
    the voxel at that step (None without a step), and the voxel's position in data units."""

    voxel: tuple[int, int, int]  # x, y, z
    position: tuple[float, float, float]  # x, y, z in the spacing's units
    step: int | None
    time: object
    time_text: str | None
    value: float | None

    def describe(self) -> str:
        """'x=3 y=4 z=5 (1.5, 2, 2.5): step 7 (0.7 s), value 0.412'."""
        x, y, z = self.voxel
        where = f"x={x} y={y} z={z} ({', '.join(f'{p:g}' for p in self.position)})"
        if self.step is None:
            return f"{where}: no step won"
        when = f" ({self.time_text})" if self.time_text != str(self.step) else ""
        return f"{where}: step {self.step}{when}, value {self.value:.6g}"


def slice_value(
    chronovolume: Chronovolume,
    series: TimeSeries,
    x: int,
    y: int,
    z: int,
    time_labels: str = "labels",
) -> SliceValue:
    """The read-out at voxel (x, y, z): the winning step from the t_index, its time from the
    chronovolume's time labels, the raw value read from `series` (the series it was integrated
    from, at its level) at that voxel and step, and the position x * dx, y * dy, z * dz."""
    cv = chronovolume
    check_prefer(time_labels)
    nz, ny, nx = cv.shape
    for axis, v, n in (("x", x, nx), ("y", y, ny), ("z", z, nz)):
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 0 <= v < n:
            raise InvalidParameterError(f"voxel {axis}={v!r} is outside the volume: 0..{n - 1}")
    x, y, z = int(x), int(y), int(z)
    dx, dy, dz = cv.spacing
    position = (x * float(dx), y * float(dy), z * float(dz))
    step = None if cv.t_index is None else int(cv.t_index[z, y, x])
    if step is None or step < 0:
        return SliceValue((x, y, z), position, None, None, None, None)
    source = _series_at_level(cv, series)
    raw = source.read_region(
        slice(step, step + 1), slice(z, z + 1), slice(y, y + 1), slice(x, x + 1)
    )
    k = cv.steps.index(step)
    labels = cv.metadata.get("time_labels")
    unit = cv.metadata.get("time_unit")
    texts = display_labels(cv.steps, labels, time_labels, unit)
    time = labels[k] if labels and len(labels) == len(cv.steps) else step
    return SliceValue((x, y, z), position, step, time, texts[k], float(np.asarray(raw).flat[0]))


def _series_at_level(cv: Chronovolume, series: TimeSeries) -> TimeSeries:
    """`series` at the level the chronovolume was integrated at, pooled as its mode pools."""
    level = int(cv.metadata.get("level") or 0)
    if level and tuple(series.volume_shape) != tuple(cv.shape):
        series = series.level(level, cv.spec.integration.pool)
    if tuple(series.volume_shape) != tuple(cv.shape):
        raise InvalidParameterError(
            f"the series is {series.volume_shape[::-1]} (x, y, z), the chronovolume "
            f"{cv.shape[::-1]}: give the series it was integrated from"
        )
    return series
