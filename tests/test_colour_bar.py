"""Colour maps and time colours that do not multiply into mud, and the data colour bar beside
the time legend (docs/semantics.md, "Colour maps and time colours" and "Legends").

Where the time colours are not chosen they follow the data TF: lightness under a colour map's
hue, rgb under a grey or white data TF. A rendered picture with `--colormap` gets a colour bar
whose pixels are the map's colours and whose ticks are 1-2-5 numbers in data units over the
value range the picture used; a white data TF gets none.
"""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

import chronocl
from chronocl.core.tf import DataTF, TFSetting, TimeTF
from chronocl.render.colorbar import data_bar
from chronocl.render.views import render

from .test_cli import cli

LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 luminance of (r, g, b)
PANEL = 160  # px, square panels of the CLI renders


def map_colours(name: str, n: int = 256) -> np.ndarray:
    from matplotlib import colormaps

    return colormaps[name](np.linspace(0.0, 1.0, n))[:, :3] * 255.0


def longest_map_run(rows: np.ndarray, name: str, near_by: float = 10.0) -> tuple[int, float]:
    """The longest horizontal run of pixels in `rows` (H, W, 3) that are the colours of map
    `name` in increasing order (each within `near_by` of one), as (its length in px, the share
    of the map it covers)."""
    lut = map_colours(name)
    best = (0, 0.0)
    for row in rows.astype(np.float64):
        dist = np.linalg.norm(row[:, None, :] - lut[None, :, :], axis=-1)
        index, near = dist.argmin(axis=1), dist.min(axis=1) < near_by
        start = 0
        for x in range(1, len(row) + 1):
            if x < len(row) and near[x] and near[x - 1] and index[x] >= index[x - 1] - 3:
                continue
            if near[start]:
                cover = (index[x - 1] - index[start]) / (len(lut) - 1)
                best = max(best, (x - start, float(cover)))
            start = x
    return best


def opaque_luminance(picture: np.ndarray) -> float:
    """Mean luminance (0..1) of the picture's pixels that are not background (black)."""
    rgb = picture[..., :3].astype(np.float64) / 255.0
    opaque = rgb.max(axis=-1) > 8 / 255
    assert opaque.mean() > 0.05  # the data shows
    return float((rgb[opaque] @ LUMA).mean())


def value_ticks(texts: list[str]) -> list[float]:
    """The colour bar's tick numbers: the numbers drawn after its title "value" or "change"."""
    title = next(i for i, t in enumerate(texts) if t in ("value", "change"))
    numbers = []
    for t in texts[title + 1 :]:
        try:
            numbers.append(float(t))
        except ValueError:
            break
    return numbers


def assert_nice(ticks: list[float], lo: float, hi: float) -> None:
    """At least three ticks inside [lo, hi], evenly spaced by 1, 2 or 5 times a power of ten,
    each a multiple of that spacing."""
    assert len(ticks) >= 3, ticks
    assert lo - 1e-9 <= ticks[0] and ticks[-1] <= hi + 1e-9, (ticks, lo, hi)
    gaps = {round(b - a, 9) for a, b in itertools.pairwise(ticks)}
    assert len(gaps) == 1, ticks
    gap = gaps.pop()
    mantissa = gap / 10 ** np.floor(np.log10(gap))
    assert round(mantissa, 6) in (1, 2, 5), ticks
    assert all(abs(t / gap - round(t / gap)) < 1e-6 for t in ticks), ticks


# ------------------------------------------------------------------ time colours follow


def test_time_colours_follow_the_data_tf_unless_chosen(tmp_path):
    white, viridis, grey = (
        DataTF(),
        DataTF().with_colormap("viridis"),
        DataTF().with_colormap("grey"),
    )
    assert TimeTF.for_data(white.points).color.preset == "rgb"
    assert TimeTF.for_data(grey.points).color.preset == "rgb"  # grey: time keeps the hue
    assert TimeTF.for_data(viridis.points).color.preset == "lightness"
    lightness = TimeTF.preset("lightness").color
    np.testing.assert_allclose(
        lightness.evaluate(np.array([0.0, 0.5, 1.0])), [[0.35] * 3, [0.675] * 3, [1.0] * 3]
    )

    # The API: no time TF given, or only an opacity shape, follows; a time colour given is kept.
    assert chronocl.make_spec("max", data_tf=viridis).time_tf.color.preset == "lightness"
    assert chronocl.make_spec("max").time_tf.color.preset == "rgb"
    hat = chronocl.make_spec("max", data_tf=viridis, time_tf="hat").time_tf
    assert (hat.color.preset, hat.alpha.shape) == ("lightness", "hat")
    assert chronocl.make_spec("max", data_tf=viridis, time_tf="rgb").time_tf.color.preset == "rgb"

    # A TF file: without time_tf it follows its data TF; with one, that is kept.
    TFSetting(data_tf=viridis).save(tmp_path / "map.json")
    assert "time_tf" not in json.loads((tmp_path / "map.json").read_text())
    assert chronocl.make_spec(tf=tmp_path / "map.json").time_tf.color.preset == "lightness"
    TFSetting(data_tf=viridis, time_tf=TimeTF.preset("warm-cool")).save(tmp_path / "wc.json")
    assert chronocl.make_spec(tf=tmp_path / "wc.json").time_tf.color.preset == "warm-cool"
    assert TFSetting.load(tmp_path / "wc.json").time_tf == TimeTF.preset("warm-cool")


def test_a_sessions_time_colours_follow_a_colormap_given_on_the_command_line():
    from chronocl.cli.render_state import _following

    viridis = DataTF().with_colormap("viridis")
    assert _following(TimeTF.preset("hat"), viridis).color.preset == "lightness"
    assert _following(TimeTF.preset("hat"), viridis).alpha.shape == "hat"  # opacity kept
    assert _following(TimeTF.preset("lightness"), DataTF()).color.preset == "rgb"
    assert _following(TimeTF.preset("warm-cool"), viridis) is None  # chosen: kept


# ------------------------------------------------------------------ CLI renders


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    """PNGs of one max picture of the vortex: with --colormap viridis (time colours left to
    follow), the same under white and rgb time colours, and with the default white data TF."""
    from PIL import Image

    root = tmp_path_factory.mktemp("colour-bar")
    store = root / "v.zarr"
    assert cli("generate", "vortex", store, "--shape", "32x32x32", "--steps", "8").returncode == 0
    runs = {
        "viridis": ["--colormap", "viridis"],
        "viridis-white": ["--colormap", "viridis", "--time-tf", "white"],
        "viridis-rgb": ["--colormap", "viridis", "--time-tf", "rgb"],
        "default": [],
    }
    out = {}
    for name, extra in runs.items():
        png = root / f"{name}.png"
        size = f"{PANEL}x{PANEL}"
        args = ["render", store, "-o", png, "--mode", "max", "--size", size, *extra]
        result = cli(*args, "--no-outline", "--no-axes")
        assert result.returncode == 0, result.stderr
        out[name] = np.asarray(Image.open(png).convert("RGB"))
    return out


def test_the_colour_bar_follows_the_map_and_is_absent_for_a_white_data_tf(renders):
    image = renders["viridis"]
    legend = image[PANEL:]  # the band under the picture (one panel: no caption band)
    length, cover = longest_map_run(legend, "viridis")
    assert length >= 80 and cover >= 0.9, (length, cover)  # the whole map, left to right
    assert longest_map_run(renders["default"][PANEL:], "viridis")[0] < 20
    # The default picture has only the time legend: its band is half as tall.
    assert renders["default"].shape[0] - PANEL < legend.shape[0]


def test_a_colour_mapped_picture_is_not_darkened_by_the_time_colours(renders):
    """Time as lightness keeps most of the map's own luminance (the picture under white time
    colours) and all of its hues; the rgb time colours would multiply it down to about a third."""
    own = opaque_luminance(renders["viridis-white"][:PANEL])
    mapped = opaque_luminance(renders["viridis"][:PANEL])
    muddy = opaque_luminance(renders["viridis-rgb"][:PANEL])
    assert mapped >= 0.65 * own, (mapped, own)
    assert muddy < 0.5 * own, (muddy, own)  # what the rule avoids


# ------------------------------------------------------------------ ticks in data units


@pytest.fixture(scope="module")
def series():
    """Values from 100 to 1100 (data units far from u in [0, 1]), rising over 10 steps."""
    rng = np.random.default_rng(7)
    z, y, x = np.mgrid[:12, :14, :16]
    blob = np.exp(-((x - 8) ** 2 + (y - 7) ** 2 + (z - 6) ** 2) / 20.0)
    steps = [100 + 1000 * blob * (0.3 + 0.07 * t) + rng.random(blob.shape) for t in range(10)]
    return chronocl.TimeSeries.from_array(np.stack(steps).astype(np.float32))


def test_colour_bar_ticks_are_nice_numbers_in_the_value_range_used(series, drawn_text):
    given = DataTF(value_range=(250.0, 950.0)).with_colormap("magma")
    cv = chronocl.integrate(series, "0:10", "max", data_tf=given, engine="numpy")
    assert cv.metadata["value_range"] == [250.0, 950.0]
    render(cv, size=(320, 320), legend=True)
    assert "value" in drawn_text
    assert_nice(value_ticks(drawn_text), 250.0, 950.0)

    # The default range (fitted to the window, not the series' global one): the ticks follow
    # the range the chronovolume records, in data units.
    drawn_text.clear()
    cv = chronocl.integrate(series, "0:4", "alpha", data_tf=DataTF().with_colormap("viridis"))
    lo, hi = cv.metadata["value_range"]
    render(cv, size=(320, 320), legend=True)
    assert_nice(value_ticks(drawn_text), lo, hi)
    assert data_bar(cv).title == "value" and (data_bar(cv).lo, data_bar(cv).hi) == (lo, hi)


def test_change_has_its_bar_over_the_change_and_white_or_count_none(series, drawn_text):
    viridis = DataTF(value_range=(100.0, 1100.0)).with_colormap("viridis")
    cv = chronocl.integrate(series, "0:10", "change", data_tf=viridis, engine="numpy")
    bar = data_bar(cv)
    assert (bar.title, bar.lo, bar.hi) == ("change", 0.0, 1000.0)
    render(cv, size=(320, 320), legend=True)
    assert_nice(value_ticks(drawn_text), 0.0, 1000.0)
    assert data_bar(chronocl.integrate(series, "0:10", "max", engine="numpy")) is None
    counted = chronocl.integrate(series, "0:10", "count", data_tf=viridis, engine="numpy")
    assert data_bar(counted) is None  # its own legend is the data TF over the fraction


def test_counts_percentages_never_overlap_on_a_narrow_panel(series, monkeypatch):
    """count's legend labels its fraction bar in quarters where they fit, else halves or the
    ends: at 176 px (the README's panels) "0%25%50%75%100%" was drawn on top of itself."""
    from PIL import ImageDraw

    boxes: list[tuple[str, float, float]] = []
    real = ImageDraw.ImageDraw.text

    def text(self, xy, content, *args, **kwargs):
        if content.endswith("%"):
            w = self.textlength(content, font=kwargs.get("font"))
            boxes.append((content, xy[0], xy[0] + w))
        return real(self, xy, content, *args, **kwargs)

    monkeypatch.setattr(ImageDraw.ImageDraw, "text", text)
    cv = chronocl.integrate(series, "0:10", "count", engine="numpy")
    for side, most in ((176, 3), (480, 5)):
        boxes.clear()
        render(cv, size=(side, side), legend=True)
        labels = [b[0] for b in boxes]
        assert labels[0] == "0%" and labels[-1] == "100%" and 2 <= len(labels) <= most
        assert all(a[2] + 4 <= b[1] for a, b in itertools.pairwise(boxes)), boxes
    assert len(labels) == 5  # the wide panel has room for the quarters


def test_the_viewer_frame_carries_the_colour_bar(series):
    from chronocl.viewer.frames import colour_bar

    cv = chronocl.integrate(series, "0:10", "max", data_tf=DataTF().with_colormap("viridis"))
    bar = colour_bar(cv)
    assert bar["title"] == "value" and bar["range"] == cv.metadata["value_range"]
    got = np.array([[int(c[i : i + 2], 16) for i in (1, 3, 5)] for c in bar["colors"]])
    np.testing.assert_allclose(got, map_colours("viridis", len(got)), atol=3)
    assert colour_bar(chronocl.integrate(series, "0:10", "max")) is None
