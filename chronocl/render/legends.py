"""The legends under a rendered panel: a bar of the time colours over the selected steps
(oldest .. newest, with the steps' time labels or numbers at 1-2-5 ticks), count's bar over the
fraction of steps, and, where the data TF is coloured, a data colour bar beside or under it with
ticks in data units (`chronocl.render.colorbar`)."""

from __future__ import annotations

import itertools

import numpy as np

from chronocl.core.tf import lut_lookup
from chronocl.core.ticks import multiples, nice_step, tick_text
from chronocl.core.time_labels import compact, display_labels, has_labels
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.colorbar import DataBar
from chronocl.render.layout import LAYOUT


def step_texts(cv: Chronovolume, prefer: str = "labels") -> list[str]:
    """The display labels of the chronovolume's steps (`chronocl.core.time_labels`)."""
    meta = cv.metadata
    return display_labels(cv.steps, meta.get("time_labels"), prefer, meta.get("time_unit"))


def legend_band(draw, cv, bar, box, beside, font, text_rgb, time_labels="labels") -> None:
    """The band under a panel: the time legend of `cv`, and its data colour bar `bar` (None:
    none) beside it or under it; a chronovolume coloured by track shows its tracks instead
    (`track_legend`)."""
    if TRACK_KEY in cv.metadata:
        track_legend(draw, cv, box, beside, font, text_rgb, time_labels)
        return
    if bar is None:
        time_legend(draw, cv, box, font, text_rgb, time_labels)
        return
    time_box, bar_box = split_legend(box, beside)
    time_legend(draw, cv, time_box, font, text_rgb, time_labels)
    # Under the time legend, the colour bar starts where the time bar does.
    title_w = 0 if beside else draw.textlength("oldest", font=font)
    draw_colour_bar(draw, bar, bar_box, font, text_rgb, title_w)


TRACK_KEY = "track_colour"  # chronocl.events.colour.META_KEY: a chronovolume coloured by track


def two_part_legend(cv: Chronovolume, bar) -> bool:
    """Whether the legend of `cv` has two parts (time and colour bar, or tracks and time)."""
    tracks = cv.metadata.get(TRACK_KEY)
    return tracks.get("by") == "time" if tracks else bar is not None


def track_legend(draw, cv, box, beside, font, text_rgb, time_labels="labels") -> None:
    """The tracks a chronovolume coloured by track shows: a swatch of each one's colour with its
    id ("tracks"), and, coloured by the time a track first shows, the time legend beside or
    under them, which says when each colour is."""
    tracks = cv.metadata[TRACK_KEY]
    if tracks.get("by") == "time":
        time_box, box = split_legend(box, beside)
        time_legend(draw, cv, time_box, font, text_rgb, time_labels)
    track_swatches(draw, tracks.get("tracks", []), box, font, text_rgb)


def track_swatches(draw, tracks: list[dict], box, font, text_rgb) -> list[int]:
    """A swatch and the id of each track of `tracks` (records with id, rgb, voxels), in id
    order, on as many lines as `box` holds; where they do not all fit, those with the most
    voxels, and "+N more". Returns the ids drawn.

    How many fit is found without laying out every count (`swatch_count`): each label is
    measured once, so a legend of thousands of tracks (a turntable draws it every frame) costs
    about as much as measuring them."""
    x0, y0, width, height = box
    title = "tracks" if tracks else "no tracks"
    draw.text((x0, y0 + 1), title, fill=text_rgb, font=font)
    top, bottom = font.getbbox("Ag")[1::2]
    line = int(bottom - top) + 6
    side = max(6, line - 6)
    start = x0 + int(draw.textlength("tracks", font=font)) + 10
    lines = max(1, (height + 4) // line)

    texts: dict[str, float] = {}  # every text measured once

    def measure(text: str) -> float:
        if text not in texts:
            texts[text] = draw.textlength(text, font=font)
        return texts[text]

    by_size = sorted(
        range(len(tracks)), key=lambda i: (-tracks[i].get("voxels", 0), tracks[i]["id"])
    )
    rank = [0] * len(tracks)  # of each track, its place by size: the first n are shown
    for place, i in enumerate(by_size):
        rank[i] = place
    # in id order (ties: by size), each track's place by size and the width of its swatch
    order = sorted(range(len(tracks)), key=lambda i: (tracks[i]["id"], rank[i]))
    items = [(rank[i], side + 4 + measure(str(tracks[i]["id"])) + 10) for i in order]
    n = swatch_count(items, lambda more: measure(f"+{more} more"), start, x0 + width, lines)
    shown = [tracks[i] for i in order if rank[i] < n]
    x, y = start, y0
    for t in shown:
        label = str(t["id"])
        w = side + 4 + measure(label) + 10
        if x > start and x + w > x0 + width:
            x, y = start, y + line
        colour = tuple(round(min(max(c, 0.0), 1.0) * 255) for c in t["rgb"])
        draw.rectangle((x, y + 2, x + side, y + 2 + side), fill=colour, outline=text_rgb)
        draw.text((x + side + 4, y + 1), label, fill=text_rgb, font=font)
        x += w
    if n < len(tracks):
        more = f"+{len(tracks) - n} more"
        if x > start and x + measure(more) > x0 + width:
            x, y = start, y + line
        draw.text((x, y + 1), more, fill=text_rgb, font=font)
    return [t["id"] for t in shown]


def swatch_count(items, tail_width, start: float, end: float, lines: int) -> int:
    """How many of the tracks fit the legend: the largest n such that the n largest, in id
    order, then "+N more" (N the rest; nothing where n is all of them), fill at most `lines`
    lines from x = `start` to `end`, a line broken before an item that would pass its end (an
    item wider than a line takes one of its own). `items`: (place by size, width) in id order;
    `tail_width(N)`: the width of "+N more".

    The n largest fit in as few lines as the n + 1 largest or fewer, the last no fuller where
    as many (greedy line breaking of a subsequence), so for one tail width whether they fit
    falls from true to false once as n grows: for each count of digits of N (the tail's
    width, where a font's digits share one width as Pillow's default font's do), from the
    fewest (n largest) on, a binary search on n. O(len(items) log len(items)) additions, and
    O(log) tail widths measured."""
    total = len(items)

    def fits(n: int) -> bool:
        more = total - n
        tail = tail_width(more) if more else 0
        used, row = 0.0, 0
        for place, w in items:
            if place >= n:
                continue
            if used and start + used + w > end:
                row, used = row + 1, 0.0
            used += w
        if used and start + used + tail > end:
            row += 1
        return row < lines

    if fits(total):
        return total
    digits = 1
    while 10 ** (digits - 1) <= total:  # N = total - n of `digits` digits: n in [lo, hi]
        hi = total - 10 ** (digits - 1)
        lo = max(0, total - (10**digits - 1))
        if fits(lo):  # the largest n in [lo, hi] that fits
            while lo < hi:
                mid = (lo + hi + 1) // 2
                lo, hi = (mid, hi) if fits(mid) else (lo, mid - 1)
            return lo
        digits += 1
    return 0


def split_legend(box, beside: bool):
    """The legend band `box` (x, y, width, height) shared by the time legend and a data colour
    bar: side by side (time on the left), or one above the other."""
    x0, y0, width, height = box
    if beside:
        time_w = round(width * LAYOUT.time_share)
        gap = 36  # "newest" and the colour bar's title must not read as one label
        return (x0, y0, time_w, height), (x0 + time_w + gap, y0, width - time_w - gap, height)
    half = (height + 8) // 2
    return (x0, y0, width, half - 8), (x0, y0 + half, width, height - half)


def draw_colour_bar(draw, bar: DataBar, box, font, text_rgb, title_w: float = 0) -> None:
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


def time_legend(draw, cv: Chronovolume, box, font, text_rgb, time_labels="labels") -> None:
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
        unit = cv.metadata.get("time_unit") if time_labels == "labels" else None
        where = (x0, y0 + bar_h, width)
        _nice_ticks(draw, values, positions_x, where, font, text_rgb, unit=unit)
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
    unit = cv.metadata.get("time_unit")
    if time_labels == "steps" or not has_labels(list(cv.steps), labels, unit):
        return [float(s) for s in cv.steps]
    if all(isinstance(t, int | float) and not isinstance(t, bool) for t in labels):
        numbers = [float(t) for t in labels]
        if all(b > a for a, b in itertools.pairwise(numbers)):
            return numbers
    return None


def _nice_ticks(draw, values, positions_x, where, font, text_rgb, most=None, unit=None) -> None:
    """Ticks at 1-2-5 multiples of `values`' span, placed where they fall between the steps,
    as many as fit 12 px apart, `most` at most (default: one per step; step numbers get
    whole-number ticks); a time `unit` follows each tick's number."""
    x0, y0, width = where
    integer = most is None and all(float(v).is_integer() for v in values)
    most = len(values) if most is None else most
    most = max(2, min(most, int(positions_x[-1] - positions_x[0]) // 16 + 1))
    while True:
        step = nice_step(values[0], values[-1], most, integer)
        ticks = multiples(values[0], values[-1], step)
        texts = [tick_text(t, step) + (f" {unit}" if unit else "") for t in ticks]
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


FRACTION_ENDS = ("no step", "every step")  # count's bar: what its two ends mean


def fraction_ramp(data_tf, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Count's bar at `n` evenly spaced fractions of the steps, 0 .. 1: the data TF's colours
    as the bar shows them (n, 3), and its opacity there (n,). The colours are weighted by the
    opacity relative to the ramp's peak, so a translucent ramp (count's own) stays legible and
    the bar is dark where it is transparent."""
    rgba = lut_lookup(data_tf.lut, np.linspace(0.0, 1.0, n))
    weight = rgba[:, 3] / max(float(rgba[:, 3].max()), 1e-6)
    shown = np.clip(rgba[:, :3] * np.maximum(weight, 0.25)[:, None], 0, 1)
    return shown, rgba[:, 3]


def _fraction_legend(draw, spec, box, font, text_rgb) -> None:
    """A bar of the data TF over the fraction of steps, for modes that show one (count)."""
    x0, y0, width, height = box
    bar_h = max(8, height // 2)
    gap = 8
    left, right = FRACTION_ENDS
    x_start = x0 + int(draw.textlength(left, font=font)) + gap
    x_end = x0 + width - int(draw.textlength(right, font=font)) - gap
    draw.text((x0, y0 + 1), left, fill=text_rgb, font=font)
    draw.text((x_end + gap, y0 + 1), right, fill=text_rgb, font=font)
    span = max(1, x_end - x_start)
    shown, _ = fraction_ramp(spec.data_tf, span)
    for i in range(span):
        colour = tuple(round(c * 255) for c in shown[i])
        draw.line([(x_start + i, y0), (x_start + i, y0 + bar_h)], fill=colour)
    # quarters where they fit 6 px apart, else halves, else the ends (a narrow panel)
    for fractions in ((0.0, 0.25, 0.5, 0.75, 1.0), (0.0, 0.5, 1.0), (0.0, 1.0)):
        widest = max(draw.textlength(f"{round(100 * f)}%", font=font) for f in fractions)
        if widest + 6 <= (span - 1) / (len(fractions) - 1):
            break
    for f in fractions:
        x = x_start + f * (span - 1)
        label = f"{round(100 * f)}%"
        w = draw.textlength(label, font=font)
        draw.line([(x, y0 + bar_h), (x, y0 + bar_h + 3)], fill=text_rgb)
        draw.text((x - w / 2, y0 + bar_h + 4), label, fill=text_rgb, font=font)
