"""Every mode's default picture of one window, with the fraction of selected steps it shows.

Part of `make demo` / `chronocl demo` (on a Gray–Scott reaction–diffusion run it generates,
`chronocl.data.simulations`) and of `chronocl demo --data PATH` (on a user's series): no
transfer function is given, so each picture is what a new user sees first. Under each panel
the fraction of the window's steps the picture shows (`chronocl.render.visible_steps`); the
same figures go to the console and to `defaults.json`.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

from chronocl import modes
from chronocl.core.atomic import atomic_file
from chronocl.core.selection import parse_selection
from chronocl.data.series import TimeSeries
from chronocl.integration.inmemory import integrate, prepare
from chronocl.render import Camera, render_views
from chronocl.render.default_view import series_early_side
from chronocl.render.views import render
from chronocl.render.visible_steps import StepsShown, steps_shown

# The measure renders each step's absence: small pictures keep it quick.
MEASURE_SIZE = (160, 160)


@dataclass(frozen=True)
class ModePicture:
    mode: str
    shown: StepsShown
    warnings: tuple[str, ...]


def default_pictures(
    series: TimeSeries,
    window: str,
    out_png: Path,
    *,
    engine: str = "opencl",
) -> list[ModePicture]:
    """Write `out_png` (one panel per mode, default TFs) and `out_png` with suffix .json; return
    what each picture shows."""
    selection = parse_selection(window, series.n_steps, series.times)
    # The default view: from the side of the first steps
    fitted = prepare(series, window).value_range
    camera = series_early_side(series, selection, fitted, Camera(30, 25, zoom=1.15))
    width = selection.width
    results, cvs, labels = [], [], []
    for mode in modes.names():
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            cv = integrate(series, window, mode, engine=engine)
        shown = steps_shown(
            series,
            window,
            mode,
            lambda c: render(c, camera, MEASURE_SIZE, jitter=False).array,
            engine=engine,
        )
        results.append(ModePicture(mode, shown, tuple(str(w.message) for w in said)))
        cvs.append(cv)
        labels.append(f"{mode}: {len(shown.shown)} of {width} steps show")
    image = render_views(cvs, camera, (320, 320), labels=labels, columns=4, axes=True, outline=True)
    image.save(out_png)
    report = {
        "window": window,
        "modes": {
            r.mode: {
                "fraction_shown": r.shown.fraction,
                "shown": list(r.shown.shown),
                "hidden": list(r.shown.hidden),
                "warnings": list(r.warnings),
            }
            for r in results
        },
    }
    with atomic_file(out_png.with_suffix(".json"), overwrite=True) as tmp:
        Path(tmp).write_text(json.dumps(report, indent=1))
    return results
