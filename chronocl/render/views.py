"""Render chronovolumes: one view, or parallel views of several under one camera, labelled,
with their legends (`chronocl.render.legends`) and laid out in a grid
(`chronocl.render.panels`); the title a saved picture carries names the data set and the windows
shown (`title_text`).

The camera frames what is visible (`chronocl.render.framing`) unless it frames the box, and a
silhouette taken along another view is integrated again for the camera where the chronovolume's
store can be reached (`chronocl.render.follow`)."""

from __future__ import annotations

import math
from collections.abc import Sequence

from chronocl.core.errors import InvalidParameterError
from chronocl.core.time_labels import check_prefer, span_text
from chronocl.data.chronovolume import Chronovolume
from chronocl.render.camera import Camera
from chronocl.render.default_view import default_camera
from chronocl.render.follow import following
from chronocl.render.framing import framed
from chronocl.render.image import Image
from chronocl.render.legends import step_texts
from chronocl.render.markers import Marker, draw_markers
from chronocl.render.panels import compose_panels
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
    markers: Sequence[Marker] | None = None,
    colour: str = "tf",
    events: object = None,
    series: object = None,
) -> Image:
    """One view of a chronovolume as an Image (displays inline in Jupyter, `.save(path)`).

    Without a camera it looks from the side where the window's first steps lie, as the command
    line does (`default_view.default_camera`: from the centres `chronocl.integrate` keeps in
    the metadata; else `Camera()`). The camera frames the visible region
    (`Camera(frame="box")`: the whole box); `time_labels`
    "labels" writes the store's time labels in the legend where it has them, "steps" the step
    numbers. A silhouette taken along another view is integrated again along the camera's
    where the store it came from can be opened, else a warning says so. `shading=True` (or a
    `Shading`) lights it from the camera by its opacity gradient; off by default (flat colour).
    `outline` draws the volume's box, `axes` the axis triad (x, y, z in red, green, blue) in
    the bottom-right corner; both off by default here (the command line draws both).
    `markers` ((x, y, z) fractions of the box, label) are drawn as labelled rings, e.g. a
    window's events: `chronocl.events(...).markers()`. `colour="track"` colours each voxel by
    the track of `events` (an EventGraph of the window) that reached it, "track-time" by when
    that track first shows, through the time TF, with a legend of the tracks: a winner mode
    only (first_hit, max, min, change; `chronocl.events.colour`), its winning steps read again
    from `series` (the TimeSeries the chronovolume came from; default: the store the
    chronovolume or the events name; data given as an array, an xarray or a URL name none, so
    give series=); the default "tf" keeps the mode's colours."""
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
        markers=markers,
        colour=colour,
        events=events,
        series=series,
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
    markers: Sequence[Marker] | None = None,
    colour: str = "tf",
    events: object = None,
    series: object = None,
) -> Image:
    """Parallel views: each chronovolume in its own panel of `size`, all under one camera.

    `volumes`, the chronovolumes already uploaded with `raycaster().upload` (and released by
    the caller), spare the upload when one set is rendered many times, e.g. a turntable.
    `shading`, `outline`, `axes`, `markers` (in every panel) and `colour` with `events` and
    `series`: as in `render` (uploaded `volumes` are drawn as they are: colour them before the
    upload).
    """
    if not chronovolumes:
        raise InvalidParameterError("nothing to render: give at least one chronovolume")
    tracks = _track_colour(colour, events, series, chronovolumes, volumes)
    camera = camera or default_camera(chronovolumes[0])
    check_prefer(time_labels)
    if volumes is None:  # uploaded volumes are drawn as they are
        chronovolumes = following(chronovolumes, camera)
        if tracks is not None:
            chronovolumes = tracks.apply(chronovolumes)
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
            panel = draw_markers(panel, camera, cv, markers) if markers else panel
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


def _track_colour(colour, events, series, chronovolumes, volumes):
    """The track colouring `colour` asks for (None: the mode's own colours), every chronovolume
    checked for it, and a series to read its steps again from found, before any work
    (`chronocl.events.colour`)."""
    from chronocl.events.colour import TrackColour, is_track_coloured, parse_colouring

    by = parse_colouring(colour)
    if by is None:
        if events is not None:
            raise InvalidParameterError(
                "events= colours the voxels by track with colour='track' (or 'track-time'); "
                "to mark the events, give markers=graph.markers() instead"
            )
        if series is not None:
            raise InvalidParameterError(
                "series= is where colour='track' (or 'track-time') reads the winning steps "
                "again; give it with colour='track' and events=, or leave it out"
            )
        return None
    if volumes is not None:
        raise InvalidParameterError(
            "uploaded volumes are drawn as they are: colour the chronovolumes by track before "
            "uploading them (chronocl.events.colour.track_colour)"
        )
    tracks = TrackColour(events, series, by)
    for cv in chronovolumes:
        if not is_track_coloured(cv):
            tracks.check(cv)
    return tracks


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
    tracks = cv.metadata.get("track_colour")
    if tracks:
        extra += ", tracks by " + ("time first shown" if tracks.get("by") == "time" else "id")
    return f"{spec.get('mode', '?')}, {order}, {steps}{extra}"


def window_text(cv: Chronovolume, time_labels: str = "labels") -> str:
    """A chronovolume's window as its steps and, where the store has time labels, their span
    with the unit: 'steps 0:16:3 (6 steps), 0 s .. 7.5 s', or 'steps 1:11 (10 steps)'."""
    from chronocl.core.selection import Selection

    sel = cv.metadata.get("selection", {})
    steps = Selection(tuple(sel.get("steps", ())), sel.get("n_steps", 1)).describe()
    n = len(cv.steps)
    text = f"steps {steps} ({n} step{'s' if n != 1 else ''})"
    texts = step_texts(cv, time_labels)
    if texts != [str(s) for s in cv.steps]:
        text += f", {span_text(texts)}"
    return text


def title_text(name: str, chronovolumes: Sequence[Chronovolume], time_labels="labels") -> str:
    """A picture's title: the data set's name and the windows its views show, each once:
    'vortex: steps 1:11 (10 steps), 0.1 s .. 1 s'."""
    windows = dict.fromkeys(window_text(cv, time_labels) for cv in chronovolumes)
    return f"{name}: {'; '.join(windows)}" if windows else name
