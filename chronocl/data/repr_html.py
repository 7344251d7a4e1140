"""The HTML summaries a notebook shows for a `TimeSeries` and a `Chronovolume` (their
`_repr_html_`): a table of what they are (shape, dtype, steps, times with their unit, spacing,
levels, where they are stored) beside a small picture, as a PNG inlined in the HTML.

A repr stays cheap: it never reads a series at full resolution. Its picture is one step (the
middle one), as a maximum along z of

- the coarsest stored level at least `TUNING.repr_min_side` voxels across (a store's
  ``levels``, a remote store's or a format's own), read whole: at 256^3 with levels, a 64^3
  block;
- or, for a series over a numpy array (`TimeSeries.from_array`), a strided view of it (every
  voxel along each axis but `TUNING.repr_picture_voxels` of them skipped: nothing is copied first);

and otherwise (a store without levels, a dask array) the middle z slice of that step at full
resolution: one layer of chunks, not the step. A chronovolume's picture composites its RGBA
front to back along z (an orthographic look down z, as a render with the default lights off
would show it) over a strided view at most `TUNING.repr_picture_voxels` voxels across. No GL,
no matplotlib.
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np

from chronocl.core.tuning import TUNING
from chronocl.data.level_sources import POOLED, STORED, AdoptedLevels
from chronocl.data.pyramid import describe_levels, level_shapes

STYLE = (
    "<style>.chronocl-repr{display:flex;gap:12px;align-items:flex-start;font-size:12px}"
    ".chronocl-repr table{border-collapse:collapse}.chronocl-repr th{text-align:left;"
    "padding:1px 8px 1px 0;font-weight:600;white-space:nowrap;vertical-align:top}"
    ".chronocl-repr td{padding:1px 0;text-align:left}.chronocl-repr img{image-rendering:"
    "pixelated;border:1px solid #8884}.chronocl-repr figcaption{color:#888;font-size:11px}"
    "</style>"
)


# -- the pictures ----------------------------------------------------------------------------
def series_picture(series) -> tuple[np.ndarray, str]:
    """A small greyscale picture (H, W) uint8 of the middle step of `series` (the module's
    docstring says which read), with a caption saying what it shows."""
    t = series.n_steps // 2
    lo, hi = series.vmin, series.vmax
    level = _coarse_level(series)
    if level is not None:
        block = np.asarray(series.level(level).data[t])
        what = f"max along z, level {level} ({'×'.join(map(str, block.shape[::-1]))})"
        plane = block.max(axis=0)
    elif series.host is not None:
        stride = max(1, math.ceil(max(series.volume_shape) / TUNING.repr_picture_voxels))
        plane = series.host[t, ::stride, ::stride, ::stride].max(axis=0)
        what = "max along z" + _sampled(stride)
    else:
        z = series.volume_shape[0] // 2
        stride = max(1, math.ceil(max(series.volume_shape[1:]) / TUNING.repr_picture_voxels))
        plane = np.asarray(series.data[t, z])[::stride, ::stride]
        what = f"slice z={z}" + _sampled(stride)
    u = (np.asarray(plane, dtype=np.float64) - lo) / ((hi - lo) or 1.0)
    image = np.nan_to_num(np.clip(u, 0.0, 1.0) * 255.0).astype(np.uint8)
    return image[::-1], f"{_time(series, t)}: {what}"


def _coarse_level(series) -> int | None:
    """The coarsest level of `series` held as it is (read without pooling level 0) whose
    longest side is at least `TUNING.repr_min_side`; None where it has none."""
    root = series.level(0)
    source = root.level_source or (STORED if root.path is not None else POOLED)
    if source is POOLED:
        return None
    shapes = level_shapes(root.volume_shape)
    n = root.n_levels
    held = range(1, n) if not isinstance(source, AdoptedLevels) else sorted(source.arrays)
    fit = [k for k in held if 1 <= k <= len(shapes) and max(shapes[k - 1]) >= TUNING.repr_min_side]
    return max(fit) if fit else None


def chronovolume_picture(cv) -> tuple[np.ndarray, str]:
    """A small RGB picture (H, W, 3) uint8 of `cv`: its premultiplied RGBA composited front
    to back along z (from the top, z largest, down) over black, on a strided view."""
    stride = max(1, math.ceil(max(cv.shape) / TUNING.repr_picture_voxels))
    rgba = cv.rgba[::stride, ::stride, ::stride]
    scale = 1.0 / 255.0 if rgba.dtype == np.uint8 else 1.0
    out = np.zeros((*rgba.shape[1:3], 3), dtype=np.float32)
    left = np.ones(rgba.shape[1:3], dtype=np.float32)  # light still let through
    for z in range(rgba.shape[0] - 1, -1, -1):
        slab = rgba[z].astype(np.float32) * scale
        out += left[..., None] * slab[..., :3]
        left *= 1.0 - np.clip(slab[..., 3], 0.0, 1.0)
    image = (np.clip(out, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return image[::-1], "composited along z" + _sampled(stride)


def png_data_url(image: np.ndarray) -> str:
    from PIL import Image as PILImage

    buf = io.BytesIO()
    PILImage.fromarray(image).save(buf, format="PNG")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


# -- the summaries ---------------------------------------------------------------------------
def series_html(series) -> str:
    """The HTML summary of `series` (its `_repr_html_`)."""
    t, z, y, x = series.shape
    rows = [
        ("shape", f"{x}×{y}×{z} (x, y, z) × {t} steps"),
        ("dtype", str(series.dtype)),
        ("values", f"{_num(series.vmin)} .. {_num(series.vmax)}"),
        ("times", _times(series)),
        ("spacing", "(" + ", ".join(_num(s) for s in series.spacing) + ") (dx, dy, dz)"),
        ("levels", describe_levels(series.volume_shape, series.n_levels)),
        ("stored", _where(series)),
    ]
    if series.level_index:
        rows.insert(0, ("level", str(series.level_index)))
    for key in ("variable", "quantity"):
        if key in series.meta:
            rows.append((key, str(series.meta[key])))
    image, caption = _picture(series_picture, series)
    title = f"TimeSeries {series.source or ''}".strip()
    return _summary(title, rows, image, caption)


def _picture(make, obj) -> tuple[np.ndarray | None, str]:
    """`make(obj)`, or no picture with one line saying why (a damaged chunk, a store out of
    reach): a repr never raises (a notebook then shows a traceback, not the summary)."""
    try:
        return make(obj)
    except Exception as exc:
        return None, f"no picture: {exc}".splitlines()[0]


def safe(summary, obj) -> str | None:
    """`summary(obj)`, or None (the plain repr shows) where even the table cannot be made."""
    try:
        return summary(obj)
    except Exception:
        return None


def chronovolume_html(cv) -> str:
    """The HTML summary of `cv` (its `_repr_html_`)."""
    meta = cv.metadata
    mode, steps, shape = cv.described()
    rows = [("shape", f"{shape}, RGBA {cv.rgba.dtype}"), ("mode", mode)]
    if steps:
        rows.append(("steps", steps))
    labels = meta.get("time_labels")
    if isinstance(labels, list) and labels:
        unit = meta.get("time_unit")
        rows.append(("times", f"{labels[0]} .. {labels[-1]}" + (f" {unit}" if unit else "")))
    rows.append(("spacing", "(" + ", ".join(_num(s) for s in cv.spacing) + ") (dx, dy, dz)"))
    if meta.get("level"):
        rows.append(("level", f"{meta['level']} (integrated from that coarse level)"))
    rows.append(("t_index", "yes" if cv.t_index is not None else "no"))
    rows.append(("from", str(meta.get("store") or meta.get("dataset") or "?")))
    rows.append(("stored", "in memory (.save(path) writes it)"))
    image, caption = _picture(chronovolume_picture, cv)
    return _summary("Chronovolume", rows, image, caption)


def _summary(
    title: str, rows: list[tuple[str, str]], image: np.ndarray | None, caption: str
) -> str:
    body = "".join(f"<tr><th>{k}</th><td>{html.escape(v)}</td></tr>" for k, v in rows)
    if image is None:
        figure = (
            f'<figure style="margin:0"><figcaption>{html.escape(caption)}</figcaption></figure>'
        )
    else:
        h, w = image.shape[:2]
        scale = TUNING.repr_shown_px / max(h, w)
        size = f'width="{round(w * scale)}" height="{round(h * scale)}"'
        figure = (
            f'<figure style="margin:0"><img src="{png_data_url(image)}" {size} '
            f'alt="{html.escape(caption)}"><figcaption>{html.escape(caption)}</figcaption>'
            "</figure>"
        )
    return (
        f'{STYLE}<div class="chronocl-repr"><div><b>{html.escape(title)}</b>'
        f"<table>{body}</table></div>{figure}</div>"
    )


def _num(v: float) -> str:
    return f"{float(v):.6g}"


def _sampled(stride: int) -> str:
    return f", 1 in {stride} voxels along each axis" if stride > 1 else ""


def _time(series, t: int) -> str:
    if not series.times:
        return f"step {t}"
    unit = series.time_unit
    return f"step {t}, time {series.times[t]}" + (f" {unit}" if unit else "")


def _times(series) -> str:
    if not series.times:
        return "none (steps by index)"
    unit = f" {series.time_unit}" if series.time_unit else " (no unit)"
    return f"{series.times[0]} .. {series.times[-1]}{unit}"


def _where(series) -> str:
    root = series.level(0)
    if root.path is not None:
        return str(root.path)
    if root.meta.get("url"):
        return str(root.meta["url"])
    return "in memory" if root.host is not None else f"not stored ({root.source or 'array'})"
