"""`make demo` / `chronocl demo`: the built-in data sets and a gallery after the paper's Figure 3.

Writes the vortex and jet series, one PNG per figure, `gallery.png` (all figures with their
captions) and `index.html`, and prints where they are and how long each took. Then every
mode's default picture of a Gray–Scott run (`defaults-gray-scott.png`, `chronocl.demo_defaults`)
with the fraction of the window's steps each shows.
"""

from __future__ import annotations

import html
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path

from rich.console import Console
from rich.table import Table

from chronocl.core.enhance import Enhance
from chronocl.core.tf import DataTF
from chronocl.data import synthetic
from chronocl.data.series import TimeSeries, write_series
from chronocl.data.simulations import simulate
from chronocl.demo_defaults import default_pictures
from chronocl.engine import get_engine
from chronocl.integration.inmemory import integrate
from chronocl.render import Camera, render_views

# Opacity 1 above the feature threshold: where every step is present, additive is white.
SURFACE = DataTF(points=[(0, 1, 1, 1, 0), (0.42, 1, 1, 1, 0), (0.5, 1, 1, 1, 1), (1, 1, 1, 1, 1)])
# Low opacity, so first hit lets one see through a step to those behind it.
FAINT = DataTF(
    points=[(0, 1, 1, 1, 0), (0.4, 1, 1, 1, 0), (0.55, 1, 1, 1, 0.22), (1, 1, 1, 1, 0.3)]
)

# change and count look the data TF up at a change or a fraction in [0, 1], not at a value.
CHANGE = DataTF(points=[(0, 1, 1, 1, 0), (0.08, 1, 1, 1, 0), (0.3, 1, 1, 1, 0.6), (1, 1, 1, 1, 1)])
OCCUPANCY = DataTF(
    points=[
        (0, 0.55, 0.25, 0.85, 0),
        (0.02, 0.55, 0.25, 0.85, 0.3),
        (0.25, 0.1, 0.75, 0.7, 0.55),
        (1, 1.0, 0.9, 0.1, 0.9),
    ]
)


@dataclass
class Figure:
    name: str
    data: str
    window: str
    modes: tuple[str, ...]
    caption: str
    args: dict = field(default_factory=dict)
    camera: Camera = field(default_factory=lambda: Camera(30, 25, zoom=1.15))


FIGURES = (
    Figure(
        "a-alpha-3-spaced",
        "vortex",
        "0:20:9",
        ("alpha",),
        "(a) Alpha compositing over 3 spaced steps of 20: the rings move from blue (oldest) "
        "through green to red (newest) without overlapping.",
    ),
    Figure(
        "b-first-hit-10",
        "vortex",
        "0:10",
        ("first_hit",),
        "(b) First temporal hit over 10 consecutive steps with a low opacity: each voxel "
        "shows the first step that reached it; steps stay distinct and see-through.",
        {"data_tf": FAINT},
    ),
    Figure(
        "c-additive-10",
        "vortex",
        "0:10",
        ("additive",),
        "(c) Additive colours over 10 consecutive steps, normalised: white where all steps "
        "overlap, a single hue where one step was alone.",
        {"data_tf": SURFACE},
    ),
    Figure(
        "e-max-3-of-10",
        "vortex",
        "0,4,9",
        ("max",),
        "(e) Maximum intensity over 3 steps of 10, coloured by the step that held the "
        "maximum: blue where the value fell, red where it rose.",
    ),
    Figure(
        "f-silhouette-3-of-30",
        "vortex",
        "0,14,29",
        ("alpha",),
        "(f) Alpha compositing with view-dependent silhouette enhancement over 3 steps of "
        "30: surfaces seen edge-on (the outlines) stay opaque, surfaces facing the viewer "
        "turn translucent.",
        {"enhance": "silhouette"},
    ),
    Figure(
        "ghi-jet-trio",
        "jet",
        "0,14,29",
        ("alpha", "additive", "max"),
        "(g, h, i) The jet over 3 steps in parallel views: alpha (the plume moved from blue "
        "to green to red), additive (white where steps share space), maximum intensity "
        "(where the value grew).",
        {"data_tf": SURFACE},
        Camera(25, 20, zoom=1.15),
    ),
    Figure(
        "j-mean-10",
        "vortex",
        "0:10",
        ("mean",),
        "(j) Mean over 10 consecutive steps: the time-averaged colour and opacity; places the "
        "rings crossed briefly are faint, where they lingered dense.",
        {"data_tf": SURFACE},
    ),
    Figure(
        "k-change-10",
        "vortex",
        "0:10",
        ("change",),
        "(k) Change over 10 steps: the largest jump between consecutive steps, coloured by "
        "when it happened (blue early, red late): where and when each place changed most.",
        {"data_tf": CHANGE},
    ),
    Figure(
        "l-count-30",
        "vortex",
        "0:30",
        ("count",),
        "(l) Occupancy over 30 steps: the fraction of steps in which a voxel was opaque, "
        "through a colour ramp (purple once, teal a quarter of the time, yellow always): the "
        "volume the rings swept.",
        {"data_tf": OCCUPANCY, "threshold": 0.5},
    ),
)


def run_demo(
    out_dir: Path,
    shape_xyz: tuple[int, int, int] = (96, 96, 96),
    n_steps: int = 30,
    size: int = 512,
    engine: str = "opencl",
    run_shape: tuple[int, int, int] = (48, 48, 48),
) -> list[Path]:
    """Write the demo under `out_dir` with engine `engine`; returns the PNG paths (the
    figures, then the default pictures of a Gray–Scott run on a grid of `run_shape`)."""
    console = Console(stderr=True)
    get_engine(engine)  # no usable OpenCL device: say so before anything is written
    out_dir.mkdir(parents=True, exist_ok=True)
    nx, ny, nz = shape_xyz
    shapes = {"vortex": (nz, ny, nx), "jet": (max(16, nz * 2 // 3), max(16, ny * 2 // 3), nx)}
    series: dict[str, TimeSeries] = {}
    timings = Table(title=f"chronocl demo -> {out_dir.resolve()}")
    for col in ("output", "what", "integrate", "render"):
        timings.add_column(col)
    for name, description in synthetic.DATASETS.items():
        t0 = time.perf_counter()
        shape = shapes[name]
        series[name] = write_series(
            out_dir / f"{name}.zarr",
            synthetic.steps(name, n_steps, shape),
            n_steps=n_steps,
            volume_shape=shape,
            dtype="float32",
            source=f"chronocl built-in '{name}': {description}",
            overwrite=True,
            progress=True,
        )
        timings.add_row(
            f"{name}.zarr",
            f"{shape[2]}x{shape[1]}x{shape[0]}, {n_steps} steps",
            f"{time.perf_counter() - t0:.2f} s (generate)",
            "",
        )

    written = []
    for fig in FIGURES:
        t0 = time.perf_counter()
        args = dict(fig.args)
        if args.get("enhance") == "silhouette":  # the silhouette follows the camera
            args["enhance"] = Enhance(
                "silhouette", k0=0.05, k1=1.5, k2=1.5, view=fig.camera.view_direction()
            )
        cvs = [integrate(series[fig.data], fig.window, m, engine=engine, **args) for m in fig.modes]
        t1 = time.perf_counter()
        image = render_views(
            cvs, fig.camera, (size, size), legend=True, labels=None if len(cvs) > 1 else []
        )
        path = image.save(out_dir / f"{fig.name}.png")
        written.append(path)
        timings.add_row(
            path.name,
            f"{fig.data} {fig.window} {'/'.join(fig.modes)}",
            f"{t1 - t0:.2f} s",
            f"{time.perf_counter() - t1:.2f} s",
        )
    _gallery(out_dir, written)
    _index(out_dir, written)
    Console().print(timings)
    console.print(f"gallery: {out_dir / 'gallery.png'}   page: {out_dir / 'index.html'}")
    t0 = time.perf_counter()
    run = TimeSeries.from_array(
        simulate("gray-scott", run_shape, 24),
        source="chronocl demo: Gray-Scott reaction-diffusion from the (0, 0, 0) corner",
    )
    path = out_dir / "defaults-gray-scott.png"
    print_shown(default_pictures(run, "0:24:3", path, engine=engine), path, console)
    console.print(f"({time.perf_counter() - t0:.1f} s)")
    return [*written, path]


def print_shown(results, path: Path, console: Console) -> None:
    """The fraction of the window's steps each default picture shows, a table on the console."""
    table = Table(title=f"default pictures -> {path.resolve()}")
    for col in ("mode", "steps shown", "hidden steps", "warnings"):
        table.add_column(col)
    for r in results:
        hidden = ", ".join(map(str, r.shown.hidden)) or "-"
        table.add_row(r.mode, f"{r.shown.fraction:.0%}", hidden, str(len(r.warnings)))
    console.print(table)


def _gallery(out_dir: Path, paths: list[Path]) -> Path:
    """All figures on one sheet with their captions."""
    from PIL import Image as PILImage
    from PIL import ImageDraw

    from chronocl.render.panels import label_font

    thumbs = [PILImage.open(p).convert("RGB") for p in paths]
    height = 360
    thumbs = [t.resize((max(1, round(t.width * height / t.height)), height)) for t in thumbs]
    font = label_font(14)
    rows, row, width = [], [], 0
    for t, fig in zip(thumbs, FIGURES, strict=True):
        if width + t.width > 1500 and row:
            rows.append(row)
            row, width = [], 0
        row.append((t, fig))
        width += t.width
    rows.append(row)
    line_h = 16
    caption_h = 8 + line_h * max(
        len(_wrap(f.caption, max(20, t.width // 8))) for r in rows for t, f in r
    )
    sheet_w = max(sum(t.width for t, _ in r) for r in rows)
    sheet = PILImage.new("RGB", (sheet_w, len(rows) * (height + caption_h)), (16, 16, 16))
    draw = ImageDraw.Draw(sheet)
    for r, items in enumerate(rows):
        x = 0
        for t, fig in items:
            y = r * (height + caption_h)
            sheet.paste(t, (x, y))
            for i, line in enumerate(_wrap(fig.caption, max(20, t.width // 8))):
                draw.text(
                    (x + 6, y + height + 4 + line_h * i), line, fill=(230, 230, 230), font=font
                )
            x += t.width
    path = out_dir / "gallery.png"
    sheet.save(path)
    return path


def _wrap(text: str, width: int) -> list[str]:
    """Lines of at most `width` characters, words (hyphenated ones too) kept whole."""
    return textwrap.wrap(text, width, break_long_words=False, break_on_hyphens=False)


def _index(out_dir: Path, paths: list[Path]) -> Path:
    items = "\n".join(
        f'<figure><img src="{html.escape(p.name)}" alt="{html.escape(f.name)}">'
        f"<figcaption>{html.escape(f.caption)}</figcaption></figure>"
        for p, f in zip(paths, FIGURES, strict=True)
    )
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>chronocl demo gallery</title>
<style>
body {{ background: #111; color: #ddd; font: 15px/1.4 system-ui, sans-serif; margin: 2em; }}
figure {{ display: inline-block; vertical-align: top; margin: 0 1.5em 2em 0; max-width: 1100px; }}
img {{ max-width: 100%; border: 1px solid #333; }}
</style></head><body>
<h1>Chronovolumes of the built-in data, after Woodring &amp; Shen (2003), Figure 3</h1>
{items}
</body></html>
"""
    path = out_dir / "index.html"
    path.write_text(page)
    return path
