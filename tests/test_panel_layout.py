"""Parallel views laid out so nothing covers a picture: captions in a band above each panel,
every panel's own legend below it, and more than four views wrapped into a grid."""

from __future__ import annotations

import numpy as np
import pytest

import chronocl
from chronocl.render.panels import compose_panels, default_columns
from chronocl.render.views import render_views

PICTURE = (255, 0, 255)  # a colour no caption, legend or background uses


def _panels(n: int, w: int = 200, h: int = 120) -> list[np.ndarray]:
    return [np.full((h, w, 3), PICTURE, np.uint8) for _ in range(n)]


@pytest.mark.parametrize(("n", "columns"), [(1, 1), (3, 3), (4, 4), (5, 3), (8, 4), (9, 3)])
def test_more_than_four_views_wrap_into_a_grid(n, columns):
    assert default_columns(n) == columns
    out = compose_panels(_panels(n), None, None, None, (0, 0, 0))
    assert out.shape[1] == columns * 200 and out.shape[0] == -(-n // columns) * 120


@pytest.mark.parametrize("n", [1, 2, 4, 6])
def test_captions_sit_in_a_band_above_each_picture_never_over_it(n):
    labels = [f"alpha, forward, a long caption for panel {i} " * (i + 1) for i in range(n)]
    out = compose_panels(_panels(n), labels, None, None, (0, 0, 0))
    picture = np.all(out == PICTURE, axis=-1)
    assert picture.sum() == n * 200 * 120  # every pixel of every picture untouched
    text = np.any(out != 0, axis=-1) & ~picture
    cols = default_columns(n)
    cell_h = out.shape[0] // -(-n // cols)
    for i in range(n):
        r, c = divmod(i, cols)
        cell = np.s_[r * cell_h : (r + 1) * cell_h, c * 200 : (c + 1) * 200]
        ys, xs = np.nonzero(picture[cell])
        top = ys.min()  # the picture's bounding box starts below the caption band
        assert (ys.min(), ys.max(), xs.min(), xs.max()) == (top, top + 119, 0, 199)
        ty, _ = np.nonzero(text[cell])
        assert ty.size and ty.max() < top  # the caption, wholly above the picture


def test_every_panel_keeps_its_own_legend(drawn_text):
    data = np.random.default_rng(0).random((10, 6, 7, 8)).astype(np.float32)
    series = chronocl.TimeSeries.from_array(data)
    cvs = [chronocl.integrate(series, "0:10", m, engine="numpy") for m in ("alpha", "count")]
    image = render_views(cvs, size=(240, 120))
    assert drawn_text.count("oldest") == 1 and drawn_text.count("no step") == 1  # each its own
    assert image.array.shape[1] == 2 * 240


def test_a_long_caption_wraps_above_the_picture_and_ends_in_an_ellipsis():
    from PIL import Image, ImageDraw

    from chronocl.render.panels import label_font, wrap_text

    draw = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    font = label_font(11)
    text = "alpha, forward, 2024-01-01 03:00 .. 21:00 (3 steps), silhouette " * 4
    lines = wrap_text(draw, text, font, 184)
    assert len(lines) == 3 and lines[-1].endswith("…")
    assert all(draw.textlength(line, font=font) <= 184 for line in lines)
    assert wrap_text(draw, "alpha, forward, steps 0:10", font, 184) == [
        "alpha, forward, steps 0:10"
    ]
