"""`chronocl render`: integrate a window in one or more modes and draw them as parallel views
in a PNG, optionally with a turntable video and the chronovolumes saved."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer

from chronocl import modes
from chronocl.cli.options import (
    AnonOpt,
    ColormapOpt,
    DeviceFormatOpt,
    DeviceOpt,
    EngineOpt,
    LevelOpt,
    NormalizeOpt,
    OrderOpt,
    ShadingOpt,
    ShadingParamsOpt,
    StorageOpt,
    TfOpt,
    ThresholdOpt,
    TimeLabelsOpt,
    TimeTfOpt,
    ValueRangeOpt,
    WindowOpt,
    err,
    local_input,
    mode_choices,
    parse_floats,
    parse_shading,
    parse_sizes,
    range_words,
    series_store,
    spec_args,
)
from chronocl.core.errors import InvalidParameterError


def render(
    ctx: typer.Context,
    store: Annotated[
        str | None,
        typer.Argument(
            metavar="[STORE]",
            help="Series store, a path or an http(s):// or s3:// URL (with --state: the "
            "session's).",
        ),
    ] = None,
    out_path: Annotated[
        Path | None,
        typer.Option("--out", "-o", metavar="OUT.png", help="Image to write (required)."),
    ] = None,
    state: Annotated[
        Path | None,
        typer.Option(
            metavar="SESSION.json",
            help="A session saved in the viewer: render what it showed (-o default: "
            "SESSION.png); options given here override it.",
        ),
    ] = None,
    mode: Annotated[
        list[str],
        typer.Option(
            help=f"Mode(s) of {mode_choices()}; repeat or comma-separate for parallel views."
        ),
    ] = [modes.DEFAULT],  # noqa: B006
    window: WindowOpt = None,
    order: OrderOpt = "forward",
    tf: TfOpt = None,
    time_tf: TimeTfOpt = None,
    colormap: ColormapOpt = None,
    value_range: ValueRangeOpt = None,
    enhance: Annotated[
        str, typer.Option(help="none, edge or silhouette (follows the camera).")
    ] = "none",
    threshold: ThresholdOpt = None,
    normalize: NormalizeOpt = "time",
    azimuth: Annotated[
        float | None,
        typer.Option(
            help="Degrees around the --up axis. Without --azimuth and --elevation the camera "
            "looks from the side where the window's first steps lie (else 30, 20)."
        ),
    ] = None,
    elevation: Annotated[
        float | None, typer.Option(help="Degrees above the plane across the --up axis.")
    ] = None,
    up: Annotated[
        str,
        typer.Option(
            help="Data axis that points up on the screen: x, y or z (azimuth turns around it)."
        ),
    ] = "y",
    zoom: Annotated[float, typer.Option(help="Magnification (1 fits what --frame frames).")] = 1.0,
    frame: Annotated[
        str,
        typer.Option(
            help="What the camera frames: visible (the non-transparent region) or box "
            "(the whole volume)."
        ),
    ] = "visible",
    projection: Annotated[str, typer.Option(help="perspective or orthographic.")] = "perspective",
    size: Annotated[str, typer.Option(help="Image (panel) size WxH, 16..8192.")] = "512x512",
    clip: Annotated[
        str | None,
        typer.Option(help="Slicing plane nx,ny,nz,offset (offset -1..1; keeps the normal's side)."),
    ] = None,
    background: Annotated[str, typer.Option(help="Colour name or #rrggbb.")] = "black",
    outline: Annotated[bool, typer.Option(help="Draw the volume's bounding box.")] = True,
    axes: Annotated[
        bool,
        typer.Option(help="Draw the axis triad (x, y, z in red, green, blue) in a corner."),
    ] = True,
    shading: ShadingOpt = False,
    shading_params: ShadingParamsOpt = None,
    time_labels: TimeLabelsOpt = "labels",
    engine: EngineOpt = "opencl",
    device: DeviceOpt = None,
    device_format: DeviceFormatOpt = "auto",
    level: LevelOpt = 0,
    turntable: Annotated[
        Path | None,
        typer.Option(metavar="OUT.mp4|OUT.gif", help="Also render a full turn as a video."),
    ] = None,
    frames: Annotated[int, typer.Option(help="Turntable frames.")] = 36,
    save_chronovolume: Annotated[
        Path | None,
        typer.Option(
            metavar="OUT.zarr|OUT.ome.zarr|OUT.vti", help="Also save the chronovolume(s)."
        ),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace outputs that exist.")] = False,
    variables: Annotated[
        list[str] | None,
        typer.Option(
            metavar="A,B", help="Variables of the store side by side: a panel each (per mode)."
        ),
    ] = None,
    events: Annotated[
        Path | None,
        typer.Option(
            metavar="EVENTS.json",
            help="Mark the window's events (from `chronocl events`) where they happened.",
        ),
    ] = None,
    colour: Annotated[
        str,
        typer.Option(
            "--colour",
            "--color",
            metavar="tf|track|track-time",
            help="What colours the voxels: tf (the transfer functions, as the mode applies "
            "them), track (each voxel the colour of the --events track that reached it, one "
            "colour per track) or track-time (that track's time colour where it first shows); "
            "track colours need a winner mode (first_hit, max, min, change).",
        ),
    ] = "tf",
    slice_at: Annotated[
        str | None,
        typer.Option(
            "--slice",
            metavar="x=N|y=N|z=N",
            help="Draw the plane of voxels at index N across x, y or z instead of a 3D view: "
            "its colours and, for modes with a winning step (first_hit, max, min, change), "
            "the map of that step with its time legend, side by side (the camera is unused).",
        ),
    ] = None,
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
) -> None:
    """Integrate a window and render it; several modes become parallel views in one image.

    Every panel shows the volume's box outline and an axis triad (x red, y green, z blue) in
    its bottom-right corner; --no-outline and --no-axes leave them out. --up names the data
    axis drawn upwards (y by default); azimuth turns around it.

    Examples:

      chronocl render vortex.zarr -o alpha.png --mode alpha --window 0:20:9

      chronocl render jet.zarr -o trio.png --mode alpha,additive,max --window 0:30:14

      chronocl render vortex.zarr -o marked.png --mode max --events events.json

      chronocl render vortex.zarr -o tracks.png --mode max --events events.json --colour track

      chronocl render vortex.zarr -o cut.png --clip 1,0,0,0 --azimuth 60 --zoom 1.4

      chronocl render plume.zarr -o side.png --up z --azimuth 0 --elevation 10

      chronocl render vortex.zarr -o bare.png --no-axes --no-outline --background white

      chronocl render vortex.zarr -o v.png --mode max --colormap viridis

      chronocl render vortex.zarr -o v.png --mode max --time-tf luminance --colormap magma

      chronocl render vortex.zarr -o s.png --enhance silhouette --turntable s.mp4

      chronocl render jet.zarr -o lit.png --mode alpha --window 0,14,29 --shading

      chronocl render jet.zarr -o lit.png --shading-params 0.2,0.8,0.5,40 --turntable lit.gif

      chronocl render ocean.zarr -o both.png --variables temp,salt --mode max

      chronocl render plume.zarr -o whole.png --frame box --zoom 1.2

      chronocl render era5.zarr -o t.png --window 0:24:6 --time-labels steps

      chronocl render vortex.zarr -o s.png --window 0:10 --mode max --slice z=40

      chronocl render --state vortex-session.json -o figure.png --size 1024x1024
    """
    if state is not None and slice_at is not None:  # a snapshot's views, not a slice (yet)
        raise InvalidParameterError("--slice does not combine with --state; leave it out")
    if state is not None:
        from chronocl.cli.render_state import given, render_state

        return render_state(state, given(ctx, locals()))
    if store is None or out_path is None:
        missing = "STORE" if store is None else "--out/-o"
        raise InvalidParameterError(f"{missing} is missing; e.g. chronocl render v.zarr -o v.png")
    from chronocl.core.enhance import Enhance
    from chronocl.core.paths import check_distinct, check_target
    from chronocl.core.time_labels import check_prefer
    from chronocl.data.formats.outputs import output_kind
    from chronocl.data.formats.outputs import save_chronovolume as save_any
    from chronocl.data.series import open_series
    from chronocl.engine import check_engine
    from chronocl.engine.device_formats import check_device_format, check_format_name
    from chronocl.events import load_events
    from chronocl.integration.inmemory import at_level, check_level, prepare
    from chronocl.render import Camera
    from chronocl.render.default_view import series_early_side
    from chronocl.render.raycaster import check_clip, check_size
    from chronocl.render.turntable import ModeViews, check_video
    from chronocl.render.views import describe, parse_color, render_views

    # Every option is checked before any work: no kernel built, no brick read, nothing written.
    modes = [m.strip() for item in mode for m in item.split(",") if m.strip()]
    if not modes:
        raise InvalidParameterError("--mode names no mode; give e.g. --mode alpha,max")
    if len(set(modes)) < len(modes):
        twice = next(m for m in modes if modes.count(m) > 1)
        raise InvalidParameterError(f"--mode {twice} is given twice; name each mode once")
    track_by = check_track_colour(colour, modes, events, variables, level)
    check_engine(engine)
    check_format_name(device_format)
    camera = Camera(
        30.0 if azimuth is None else azimuth,
        20.0 if elevation is None else elevation,
        zoom,
        projection=projection,
        frame=frame,
        up=up,
    )
    check_prefer(time_labels)
    panel = check_size(parse_sizes(size, 2, "WxH", "512x512"))
    parse_color(background)
    clip_plane = check_clip(parse_floats(clip, 4, "clip")) if clip else None
    lighting = parse_shading(shading, shading_params)
    if turntable is not None:
        check_video(turntable, frames)
    elif not 2 <= frames <= 3600:
        raise InvalidParameterError(f"turntable frames is {frames}; use 2 to 3600")
    Enhance(enhance)  # an unknown kind fails here
    check_slice_options(slice_at, modes, variables, turntable)
    saves = chronovolume_paths(save_chronovolume, modes)
    for path in saves:
        output_kind(path)
    store, storage_options = series_store(store, anon, storage_option)
    args = spec_args(tf, time_tf, order, enhance, threshold, normalize, colormap, value_range)
    outputs = [out_path, *([turntable] if turntable is not None else []), *saves]
    check_distinct(outputs)
    for path in outputs:
        check_target(path, overwrite, [local_input(store), tf, events])
    graph = None if events is None else load_events(events)  # one line if it is not one
    series = open_series(store, storage_options=storage_options)
    if graph is not None:
        check_events(graph, events, series)
    names = [n.strip() for item in variables or [] for n in item.split(",") if n.strip()]
    if names and (turntable is not None or saves):
        raise InvalidParameterError(
            "--variables draws one image; leave out --turntable and --save-chronovolume"
        )
    if not names and len(series.variables) > 1:
        err.print(
            f"note: {store} holds {', '.join(series.variables)}; drawing {series.variables[0]}"
        )
    picked = [series.variable(n) for n in names] or [series]
    for one in picked:
        check_level(one, level)
    if slice_at is not None:  # inside the volume at the level drawn, before any work
        from chronocl.render.slices import parse_slice

        at = picked[0].level(level) if level else picked[0]
        slice_at = str(parse_slice(slice_at, at.volume_shape))
    # window, modes, order, transfer functions, normalisation, threshold
    jobs = [prepare(one, window, m, None, args) for one in picked for m in modes]
    selection = jobs[0].selection  # one window for every variable and mode
    if azimuth is None and elevation is None:  # the default view: from the first steps' side
        camera = series_early_side(picked[0], selection, jobs[0].value_range, camera)
    tracks = None
    if track_by is not None:  # the events cover the window: checked before any step is read
        from chronocl.events.colour import TrackColour, check_records, check_steps

        check_records(graph)
        check_steps(graph, selection.steps, series.volume_shape)
        tracks = TrackColour(graph, series, track_by)
    if device_format != "auto":  # over each level's value range, which it quantises
        for job in jobs:
            check_device_format(device_format, engine, *at_level(job, level).format_input())
    views = ModeViews(
        picked[0],
        window,
        modes,
        panel,
        engine=engine,
        device=device,
        spec_args=args,
        draw_args=dict(
            background=background,
            clip=clip_plane,
            outline=outline,
            axes=axes,
            shading=lighting,
            time_labels=time_labels,
            markers=None if graph is None else graph.markers(selection.steps),
        ),
        level=level,
        device_format=device_format,
        tracks=tracks,
    )

    t0 = time.perf_counter()
    cvs = [cv for one in picked for cv in replace(views, series=one).integrate(camera)]
    if tracks is not None:
        note_untracked(cvs)
    image = None
    if slice_at is not None:
        from chronocl.render.slices import render_slice

        image = render_slice(
            cvs[0], slice_at, panel, background=background, time_labels=time_labels
        )
    elif names:  # one panel per variable and mode, one camera, each captioned with its variable
        captions = [
            f"{n}: {describe(cv)}"
            for n, cv in zip([n for n in names for _ in modes], cvs, strict=True)
        ]
        rows = {"columns": len(modes)} if len(modes) > 1 else {}  # a row per variable
        image = render_views(cvs, camera, panel, labels=captions, **rows, **views.draw_args)
    t1 = time.perf_counter()
    (views.draw(cvs, camera) if image is None else image).save(out_path, overwrite=overwrite)
    ranges = range_words(jobs[: len(modes)])
    err.print(
        f"wrote {out_path} ({', '.join(modes)}; {ranges}; integrate {t1 - t0:.2f} s, "
        f"render {time.perf_counter() - t1:.2f} s)"
    )
    for cv, path in zip(cvs, saves, strict=False):
        save_any(cv, path, overwrite=overwrite)
        err.print(f"wrote {path}")
    if turntable is not None:
        views.turntable(cvs, camera, turntable, frames, overwrite=overwrite, progress=True)
        err.print(f"wrote {turntable} ({frames} frames)")


def check_slice_options(slice_at, modes, variables, turntable) -> None:
    """One line, before any work, where --slice cannot draw what the other options ask for: it
    draws one mode of one variable as one picture."""
    if slice_at is None:
        return
    from chronocl.render.slices import parse_slice

    parse_slice(slice_at)  # its form; its index once the volume's shape is known
    if len(modes) > 1:
        raise InvalidParameterError(
            f"--slice draws one mode; give one --mode (not {','.join(modes)})"
        )
    if variables:
        raise InvalidParameterError("--slice draws one variable; leave out --variables")
    if turntable is not None:
        raise InvalidParameterError("--slice draws a picture, not a turn; leave out --turntable")


def check_track_colour(colour, modes, events, variables, level) -> str | None:
    """The track colouring --colour asks for ("id", "time"; None: the TFs'), or one line where
    it cannot be: a mode without a winning step per voxel, no --events, several variables or a
    coarse level (the events label the series' own steps)."""
    from chronocl.events.colour import check_mode, parse_colouring

    by = parse_colouring(colour)
    if by is None:
        return None
    for m in modes:
        check_mode(m)
    if events is None:
        raise InvalidParameterError(
            f"--colour {colour} colours by the tracks of --events EVENTS.json; find them with "
            "chronocl events STORE --window ... -o EVENTS.json"
        )
    if variables:
        raise InvalidParameterError(
            f"--colour {colour} draws the tracks of one variable; leave out --variables"
        )
    if level != 0:
        raise InvalidParameterError(
            f"--colour {colour} labels the series' own steps (level 0), as chronocl events "
            "did; leave out --level"
        )
    return by


UNTRACKED_NOTE = 0.25  # of a panel's opacity left transparent by --colour track: say so


def note_untracked(cvs) -> None:
    """A note for each track-coloured panel that lost much of its opacity: voxels outside every
    feature at their winning step are transparent (`chronocl.events.colour`)."""
    from chronocl.events.colour import META_KEY

    for cv in cvs:
        share = cv.metadata.get(META_KEY, {}).get("untracked_opacity", 0.0)
        if share > UNTRACKED_NOTE:
            mode = cv.metadata.get("spec", {}).get("mode", "?")
            err.print(
                f"note: {mode}: {share:.0%} of its opacity lies in no feature at the voxel's "
                "winning step (under the events' threshold) and is left transparent; events "
                "found at a lower threshold, or with this render's TF and threshold, keep more"
            )


def chronovolume_paths(path: Path | None, modes: list[str]) -> list[Path]:
    """One path per mode: NAME-MODE.SUFFIX when there are several (.ome.zarr kept whole)."""
    if path is None:
        return []
    if len(modes) == 1:
        return [path]
    name = path.name
    suffix = ".ome.zarr" if name.lower().endswith(".ome.zarr") else path.suffix
    stem = name[: len(name) - len(suffix)] if suffix else name
    return [path.with_name(f"{stem}-{m}{suffix}") for m in modes]


def check_events(graph, path: Path, series) -> None:
    """One line, before any work, where the events file cannot mark this store's pictures: its
    records are not an events file's, or its features lie in a volume of another shape."""
    from chronocl.core.errors import InvalidDataError

    try:
        graph.markers()
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InvalidDataError(
            f"{str(path)!r} is not an events file chronocl can read ({type(exc).__name__}: "
            f"{exc}); write it with chronocl events"
        ) from None
    shape = graph.meta.get("volume_shape_zyx")
    if shape is not None and list(shape) != list(series.volume_shape):
        raise InvalidParameterError(
            f"{str(path)!r} holds events of a {'x'.join(map(str, shape[::-1]))} volume, the "
            f"store's is {'x'.join(map(str, series.volume_shape[::-1]))}; give the events "
            "chronocl events found in this store"
        )
