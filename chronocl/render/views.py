"""Render chronovolumes: one view, or parallel views of several under one camera, labelled,
with a legend bar of the time colours (oldest .. newest, the steps' time labels or numbers)
and, where the data TF is coloured (a colour map), a data colour bar beside it with ticks in
data units (`chronocl.render.colorbar`).

The camera frames what is visible (`chronocl.render.framing`) unless it frames the box, and a
silhouette taken along another view is integrated again for the camera where the chronovolume's
store can be reached (`chronocl.render.follow`)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.core.tf import lut_lookup
from chronocl.core.ticks import multiples, nice_step, tick_text
from chronocl.core.time_labels import check_prefer, compact, display_labels, has_labels, span_text
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera
from chronocl.render.colorbar import DataBar, data_bar
from chronocl.render.follow import following
from chronocl.render.framing import framed
from chronocl.render.image import Image
from chronocl.render.raycaster import Raycaster, Volume, check_clip, check_size
from chronocl.render.shading import Shading, as_shading
from chronocl.render.triad import draw_triad

_raycaster: Raycaster | None = None


def raycaster() -> Raycaster:
    """The process's raycaster (created on first use)."""
    global _raycaster
    if _raycaster is None:
        _raycaster = Raycaster()
    return _raycaster


def parse_color(color: object) -> tuple[float, float, float]:
    """'#rrggbb', a colour name Pillow knows, or three numbers in [0, 1]."""
    if isinstance(color, str):
        from PIL import ImageColor

        try:
            r, g, b = ImageColor.getrgb(color)[:3]
        except ValueError:
            raise InvalidParameterError(
                f"unknown colour {color!r}; use #rrggbb or a name such as black"
            ) from None
        return r / 255, g / 255, b / 255
    try:
        rgb = tuple(float(c) for c in color)  # type: ignore[union-attr]
    except TypeError:
        rgb = ()
    if len(rgb) != 3 or not all(math.isfinite(c) and 0 <= c <= 1 for c in rgb):
        raise InvalidParameterError(f"colour {color!r} must be three numbers in [0, 1]")
    return rgb  # type: ignore[return-value]


def render(
    chronovolume: Chronovolume,
    camera: Camera | None = None,
    size: tuple[int, int] = (512, 512),
    *,
    background: object = "black",
    clip: tuple[float, float, float, float] | None = None,
    jitter: bool = True,
    step: float = 1.0,
    outline: bool = False,
    axes: bool = False,
    nearest: bool = False,
    label: str | None = None,
    legend: bool = False,
    shading: Shading | bool | None = None,
    time_labels: str = "labels",
) -> Image:
    """One view of a chronovolume as an Image (displays inline in Jupyter, `.save(path)`).

    The camera frames the visible region (`Camera(frame="box")`: the whole box); `time_labels`
    "labels" writes the store's time labels in the legend where it has them, "steps" the step
    numbers. A silhouette taken along another view is integrated again along the camera's
    where the store it came from can be opened, else a warning says so. `shading=True` (or a
    `Shading`) lights it from the camera by its opacity gradient; off by default (flat colour).
    `outline` draws the volume's box, `axes` the axis triad (x, y, z in red, green, blue) in
    the bottom-right corner; both off by default here (the command line draws both)."""
    return render_views(
        [chronovolume],
        camera,
        size,
        background=background,
        clip=clip,
        jitter=jitter,
        step=step,
        outline=outline,
        axes=axes,
        nearest=nearest,
        labels=[label] if label else None,
        legend=legend,
        shading=shading,
        time_labels=time_labels,
    )


def render_views(
    chronovolumes: Sequence[Chronovolume],
    camera: Camera | None = None,
    size: tuple[int, int] = (384, 384),
    *,
    background: object = "black",
    clip: tuple[float, float, float, float] | None = None,
    jitter: bool = True,
    step: float = 1.0,
    outline: bool = False,
    axes: bool = False,
    nearest: bool = False,
    labels: Sequence[str] | None = None,
    legend: bool = True,
    columns: int | None = None,
    volumes: Sequence[Volume] | None = None,
    shading: Shading | bool | None = None,
    time_labels: str = "labels",
) -> Image:
    """Parallel views: each chronovolume in its own panel of `size`, all under one camera.

    `volumes`, the chronovolumes already uploaded with `raycaster().upload` (and released by
    the caller), spare the upload when one set is rendered many times, e.g. a turntable.
    `shading`, `outline` and `axes`: as in `render`.
    """
    if not chronovolumes:
        raise InvalidParameterError("nothing to render: give at least one chronovolume")
    camera = camera or Camera()
    check_prefer(time_labels)
    if volumes is None:  # uploaded volumes are drawn as they are
        chronovolumes = following(chronovolumes, camera)
    camera = framed(camera, chronovolumes)
    w, h = check_size(size)
    bg = parse_color(background)
    clip = None if clip is None else check_clip(clip)
    lighting = as_shading(shading)
    rc = raycaster()
    panels = []
    for i, cv in enumerate(chronovolumes):
        volume = volumes[i] if volumes is not None else rc.upload(cv, nearest=nearest)
        try:
            panel = rc.draw(
                volume,
                camera,
                (w, h),
                background=bg,
                clip=clip,
                jitter=jitter,
                step=step,
                outline=outline,
                shading=lighting,
            )
            panels.append(draw_triad(panel, camera) if axes else panel)
        finally:
            if volumes is None:
                volume.release()
    if labels is None and len(chronovolumes) > 1:
        labels = [describe(cv, time_labels) for cv in chronovolumes]
    if not labels and not legend and len(panels) == 1:
        return Image(panels[0])
    legend_of = chronovolumes if legend else None
    return Image(compose_panels(panels, labels, legend_of, columns, bg, time_labels))


def step_texts(cv: Chronovolume, prefer: str = "labels") -> list[str]:
    """The display labels of the chronovolume's steps (`chronocl.core.time_labels`)."""
    return display_labels(cv.steps, cv.metadata.get("time_labels"), prefer)


def describe(cv: Chronovolume, time_labels: str = "labels") -> str:
    """Panel label: mode, order and window, e.g. 'alpha, forward, steps 0:20:9', or with
    time labels 'alpha, forward, 2024-01-01 06:00 .. 18:00 (3 steps)'."""
    from chronocl.core.selection import Selection

    spec = cv.metadata.get("spec", {})
    order = spec.get("order", "forward")
    order = order if isinstance(order, str) else "importance " + ",".join(map(str, order))
    sel = cv.metadata.get("selection", {})
    steps = "steps " + Selection(tuple(sel.get("steps", ())), sel.get("n_steps", 1)).describe()
    texts = step_texts(cv, time_labels)
    if texts != [str(s) for s in cv.steps]:
        steps = f"{span_text(texts)} ({len(texts)} step{'s' if len(texts) > 1 else ''})"
    extra = ""
    enhance = spec.get("enhance", {}).get("kind", "none")
    if enhance != "none":
        extra = f", {enhance}"
    return f"{spec.get('mode', '?')}, {order}, {steps}{extra}"


def label_font(size: int):
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType sizes
        return ImageFont.load_default()


def default_columns(n: int) -> int:
    """Panels per row: one row up to four views, then the fewest rows of at most four, evened
    out (5 -> 3 + 2, 8 -> 4 + 4, 9 -> 3 x 3)."""
    if n <= 4:
        return max(1, n)
    return math.ceil(n / math.ceil(n / 4))


def caption_height(font, lines: int = 1) -> int:
    """The height of the band above a panel that holds a caption of `lines` lines."""
    return line_height(font) * lines + 12


def line_height(font) -> int:
    top, bottom = font.getbbox("Ag,|")[1::2]
    return int(bottom - top) + 3


CAPTION_LINES = 3  # a caption wraps onto at most this many lines, then ends in '…'


def wrap_text(draw, text: str, font, width: float, most: int = CAPTION_LINES) -> list[str]:
    """`text` broken at spaces into lines of at most `width` pixels, at most `most` of them (the
    last shortened with '…' when the text is longer still)."""
    lines: list[str] = []
    for word in text.split(" "):
        if lines and draw.textlength(f"{lines[-1]} {word}", font=font) <= width:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word)
    if len(lines) > most:
        lines = [*lines[: most - 1], " ".join(lines[most - 1 :])]
    last = lines[-1]
    if draw.textlength(last, font=font) > width:
        while last and draw.textlength(last + "…", font=font) > width:
            last = last[:-1]
        lines[-1] = last.rstrip(" ,") + "…"
    return lines


def compose_panels(panels, labels, legend_of, columns, bg, time_labels="labels") -> np.ndarray:
    """The panels in a grid (`columns` per row, else `default_columns`), each in a cell of its
    own: its caption in a band above the picture, never over it, and, with `legend_of`, the
    legend of its own chronovolume in a band below."""
    from PIL import Image as PILImage
    from PIL import ImageDraw

    n = len(panels)
    h, w, _ = panels[0].shape
    cols = columns or default_columns(n)
    rows = math.ceil(n / cols)
    text_rgb = (20, 20, 20) if sum(bg) > 1.5 else (235, 235, 235)
    font = label_font(max(11, min(w, h) // 26))
    measure = ImageDraw.Draw(PILImage.new("RGB", (1, 1)))
    wrapped = [wrap_text(measure, t, font, w - 16) for t in labels or []]
    cap_h = caption_height(font, max(map(len, wrapped))) if wrapped else 0
    bars = [data_bar(cv) for cv in legend_of] if legend_of else []
    # A data colour bar sits beside the time legend where the band is wide enough for both
    # to show several ticks, else under it (the band twice as tall).
    beside = w - 16 >= measure.textlength("0" * BESIDE_MIN_DIGITS, font=font)
    legend_h = max(36, h // 8) if legend_of else 0
    if any(bars) and not beside:
        legend_h *= 2
    cell_h = cap_h + h + legend_h
    canvas = PILImage.new("RGB", (cols * w, rows * cell_h), tuple(round(c * 255) for c in bg))
    draw = ImageDraw.Draw(canvas)
    for i, panel in enumerate(panels):
        r, c = divmod(i, cols)
        x, y = c * w, r * cell_h
        canvas.paste(PILImage.fromarray(panel), (x, y + cap_h))
        if i < len(wrapped):
            text = "\n".join(wrapped[i])
            draw.text((x + 8, y + 6), text, fill=text_rgb, font=font, spacing=3)
        if legend_of:
            k = i if i < len(legend_of) else 0
            box = (x + 8, y + cap_h + h + 4, w - 16, legend_h - 8)
            if bars[k] is None:
                _legend(draw, legend_of[k], box, font, text_rgb, time_labels)
                continue
            time_box, bar_box = _split_legend(box, beside)
            _legend(draw, legend_of[k], time_box, font, text_rgb, time_labels)
            # Under the time legend, the colour bar starts where the time bar does.
            title_w = 0 if beside else draw.textlength("oldest", font=font)
            _colour_bar(draw, bars[k], bar_box, font, text_rgb, title_w)
    return np.asarray(canvas)


# A legend band as wide as this many digits holds a time legend and a colour bar side by side.
BESIDE_MIN_DIGITS = 64
TIME_SHARE = 0.55  # of a shared band's width, the time legend's


def _split_legend(box, beside: bool):
    """The legend band `box` (x, y, width, height) shared by the time legend and a data colour
    bar: side by side (time on the left), or one above the other."""
    x0, y0, width, height = box
    if beside:
        time_w = round(width * TIME_SHARE)
        gap = 36  # "newest" and the colour bar's title must not read as one label
        return (x0, y0, time_w, height), (x0 + time_w + gap, y0, width - time_w - gap, height)
    half = (height + 8) // 2
    return (x0, y0, width, half - 8), (x0, y0 + half, width, height - half)


def _colour_bar(draw, bar: DataBar, box, font, text_rgb, title_w: float = 0) -> None:
    """The data TF's colours rgb_d over the value range, its title ("value") on the left in
    a column `title_w` wide at least, 1-2-5 ticks in data units under it
    (`chronocl.render.colorbar`)."""
    x0, y0, width, height = box
    bar_h = max(8, height // 2)
    x_start = x0 + int(max(title_w, draw.textlength(bar.title, font=font))) + 8
    span = max(2, x0 + width - x_start)
    draw.text((x0, y0 + 1), bar.title, fill=text_rgb, font=font)
    rgb = np.clip(bar.rgb(span), 0.0, 1.0)
    for i in range(span):
        colour = tuple(round(c * 255) for c in rgb[i])
        draw.line([(x_start + i, y0), (x_start + i, y0 + bar_h)], fill=colour)
    ends = [x_start, x_start + span - 1]
    _nice_ticks(draw, [bar.lo, bar.hi], ends, (x0, y0 + bar_h, width), font, text_rgb, most=10)


def _legend(draw, cv: Chronovolume, box, font, text_rgb, time_labels="labels") -> None:
    """A bar of the time colours over the selected steps, oldest on the left."""
    from chronocl.modes.spec import IntegrationSpec

    spec = IntegrationSpec.from_dict(cv.metadata["spec"])
    if spec.integration.legend == "fraction":
        _fraction_legend(draw, spec, box, font, text_rgb)
        return
    steps = cv.steps
    n_steps = cv.metadata["selection"]["n_steps"]
    positions = spec.time_tf.positions_of(steps, n_steps)
    x0, y0, width, height = box
    bar_h = max(8, height // 2)
    gap = 8
    x_start = x0 + int(draw.textlength("oldest", font=font)) + gap
    x_end = x0 + width - int(draw.textlength("newest", font=font)) - gap
    draw.text((x0, y0 + 1), "oldest", fill=text_rgb, font=font)
    draw.text((x_end + gap, y0 + 1), "newest", fill=text_rgb, font=font)
    span = max(1, x_end - x_start)
    # Colour by position within the window: blend between the steps' colours.
    xs = np.linspace(0.0, 1.0, span)
    p_of_x = (
        np.interp(xs, np.linspace(0, 1, len(positions)), positions)
        if len(steps) > 1
        else (np.full(span, positions[0]))
    )
    rgb, alpha = spec.time_tf.evaluate(p_of_x)
    shown = np.clip(rgb * np.maximum(alpha, 0.25)[:, None], 0, 1)
    for i in range(span):
        colour = tuple(round(c * 255) for c in shown[i])
        draw.line([(x_start + i, y0), (x_start + i, y0 + bar_h)], fill=colour)
    positions_x = [x_start + (k / max(1, len(steps) - 1)) * (span - 1) for k in range(len(steps))]
    values = _tick_values(cv, time_labels)
    if values is not None and len(steps) > 1:
        _nice_ticks(draw, values, positions_x, (x0, y0 + bar_h, width), font, text_rgb)
        return
    # Text or date labels: the steps that fit without overlapping; the oldest and newest always.
    texts = compact(step_texts(cv, time_labels))
    shown: list[tuple[float, float]] = []  # the labels' extents, 10 px apart at least
    for k in [0, len(steps) - 1, *range(1, len(steps) - 1)]:
        x, w = positions_x[k], draw.textlength(texts[k], font=font)
        left = min(max(x - w / 2, x0), x0 + width - w)  # centred on its tick, inside the bar
        if all(left + w + 10 <= a or left >= b + 10 for a, b in shown):
            shown.append((left, left + w))
            draw.line([(x, y0 + bar_h), (x, y0 + bar_h + 3)], fill=text_rgb)
            draw.text((left, y0 + bar_h + 4), texts[k], fill=text_rgb, font=font)


def _tick_values(cv: Chronovolume, time_labels: str) -> list[float] | None:
    """The number each selected step stands for on the legend's axis: its time where every
    label is a number (increasing), its step number where the store has no labels or they are
    not wanted; None for text and date labels, which are shown as they are."""
    labels = cv.metadata.get("time_labels")
    if time_labels == "steps" or not has_labels(list(cv.steps), labels):
        return [float(s) for s in cv.steps]
    if all(isinstance(t, int | float) and not isinstance(t, bool) for t in labels):
        numbers = [float(t) for t in labels]
        if all(b > a for a, b in itertools.pairwise(numbers)):
            return numbers
    return None


def _nice_ticks(draw, values, positions_x, where, font, text_rgb, most=None) -> None:
    """Ticks at 1-2-5 multiples of `values`' span, placed where they fall between the steps,
    as many as fit 12 px apart, `most` at most (default: one per step; step numbers get
    whole-number ticks)."""
    x0, y0, width = where
    integer = most is None and all(float(v).is_integer() for v in values)
    most = len(values) if most is None else most
    most = max(2, min(most, int(positions_x[-1] - positions_x[0]) // 16 + 1))
    while True:
        step = nice_step(values[0], values[-1], most, integer)
        ticks = multiples(values[0], values[-1], step)
        texts = [tick_text(t, step) for t in ticks]
        widest = max(draw.textlength(t, font=font) for t in texts) if texts else 0
        if most <= 2 or len(ticks) * (widest + 12) <= positions_x[-1] - positions_x[0] + widest:
            break
        most -= 1
    for t, text in zip(ticks, texts, strict=True):
        x = float(np.interp(t, values, positions_x))
        w = draw.textlength(text, font=font)
        left = min(max(x - w / 2, x0), x0 + width - w)
        draw.line([(x, y0), (x, y0 + 3)], fill=text_rgb)
        draw.text((left, y0 + 4), text, fill=text_rgb, font=font)


def _fraction_legend(draw, spec, box, font, text_rgb) -> None:
    """A bar of the data TF over the fraction of steps, for modes that show one (count)."""
    x0, y0, width, height = box
    bar_h = max(8, height // 2)
    gap = 8
    left, right = "no step", "every step"
    x_start = x0 + int(draw.textlength(left, font=font)) + gap
    x_end = x0 + width - int(draw.textlength(right, font=font)) - gap
    draw.text((x0, y0 + 1), left, fill=text_rgb, font=font)
    draw.text((x_end + gap, y0 + 1), right, fill=text_rgb, font=font)
    span = max(1, x_end - x_start)
    rgba = lut_lookup(spec.data_tf.lut, np.linspace(0.0, 1.0, span))
    shown = np.clip(rgba[:, :3] * np.maximum(rgba[:, 3], 0.25)[:, None], 0, 1)
    for i in range(span):
        colour = tuple(round(c * 255) for c in shown[i])
        draw.line([(x_start + i, y0), (x_start + i, y0 + bar_h)], fill=colour)
    for f in (0.0, 0.25, 0.5, 0.75, 1.0):
        x = x_start + f * (span - 1)
        label = f"{round(100 * f)}%"
        draw.line([(x, y0 + bar_h), (x, y0 + bar_h + 3)], fill=text_rgb)
        draw.text((x - 4 * len(label), y0 + bar_h + 4), label, fill=text_rgb, font=font)
