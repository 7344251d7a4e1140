"""Panels laid out in a grid, each in a cell of its own: its caption wrapped in a band above the
picture (never over it) and its own legends in a band below (`chronocl.render.legends`); a
title (the data set and window, as the viewer's Save PNG gives it) in a band over the grid.
`compose` also returns where it put each part (`Layout`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from chronocl.render.colorbar import data_bar
from chronocl.render.layout import LAYOUT
from chronocl.render.legends import TRACK_KEY, legend_band, two_part_legend


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


def wrap_text(draw, text: str, font, width: float, most: int = LAYOUT.caption_lines) -> list[str]:
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


Box = tuple[int, int, int, int]  # x, y, width, height in pixels


@dataclass
class Layout:
    """Where `compose` put each part of its image: the title band (None: no title) and, per
    panel, its caption band, its picture and its legend band (None: no legend)."""

    title: Box | None = None
    captions: list[Box] = field(default_factory=list)
    pictures: list[Box] = field(default_factory=list)
    legends: list[Box | None] = field(default_factory=list)


def compose_panels(panels, labels, legend_of, columns, bg, time_labels="labels") -> np.ndarray:
    """`compose`'s image without a title."""
    return compose(panels, labels, legend_of, columns, bg, time_labels)[0]


def compose(
    panels, labels, legend_of, columns, bg, time_labels="labels", title: str | None = None
) -> tuple[np.ndarray, Layout]:
    """The panels in a grid (`columns` per row, else `default_columns`), each in a cell of its
    own: its caption in a band above the picture, never over it, and, with `legend_of`, the
    legend of its own chronovolume in a band below; with a `title`, a band over the grid holds
    it (wrapped). Returns the image and its `Layout`."""
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
    titled = wrap_text(measure, title, font, cols * w - 16) if title else []
    title_h = caption_height(font, len(titled)) if titled else 0
    # a chronovolume coloured by track shows its tracks, not its data TF's colours
    bars = [None if TRACK_KEY in cv.metadata else data_bar(cv) for cv in legend_of or []]
    # A data colour bar sits beside the time legend where the band is wide enough for both
    # to show several ticks, else under it (the band twice as tall).
    beside = w - 16 >= measure.textlength("0" * LAYOUT.beside_min_digits, font=font)
    legend_h = max(36, h // 8) if legend_of else 0
    two = [two_part_legend(cv, bar) for cv, bar in zip(legend_of or [], bars, strict=True)]
    if any(two) and not beside:
        legend_h *= 2
    cell_h = cap_h + h + legend_h
    size = (cols * w, title_h + rows * cell_h)
    canvas = PILImage.new("RGB", size, tuple(round(c * 255) for c in bg))
    draw = ImageDraw.Draw(canvas)
    layout = Layout(title=(0, 0, size[0], title_h) if titled else None)
    if titled:
        draw.text((8, 6), "\n".join(titled), fill=text_rgb, font=font, spacing=3)
    for i, panel in enumerate(panels):
        r, c = divmod(i, cols)
        x, y = c * w, title_h + r * cell_h
        canvas.paste(PILImage.fromarray(panel), (x, y + cap_h))
        layout.captions.append((x, y, w, cap_h))
        layout.pictures.append((x, y + cap_h, w, h))
        if i < len(wrapped):
            text = "\n".join(wrapped[i])
            draw.text((x + 8, y + 6), text, fill=text_rgb, font=font, spacing=3)
        layout.legends.append((x, y + cap_h + h, w, legend_h) if legend_of else None)
        if legend_of:
            k = i if i < len(legend_of) else 0
            box = (x + 8, y + cap_h + h + 4, w - 16, legend_h - 8)
            legend_band(draw, legend_of[k], bars[k], box, beside, font, text_rgb, time_labels)
    return np.asarray(canvas), layout
