"""The `chronocl` command line: a thin layer over the public API.

Errors that chronocl raises on bad input print one line on stderr and exit
with code 2, never a traceback.
"""

from __future__ import annotations

import errno
import json
import os
import sys
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from chronocl.core.errors import ChronoclError, InvalidParameterError

err = Console(stderr=True)
out = Console()

app = typer.Typer(
    name="chronocl",
    help="""Chronovolumes: integrate a window of time steps of a time-varying volume into one
RGBA volume through a temporal transfer function (Woodring & Shen 2003).

Examples:

  chronocl generate vortex vortex.zarr --shape 64x64x64 --steps 30

  chronocl ingest 'jet/jet_*.raw' -o jet.zarr --dims 128 128 128 --dtype float32

  chronocl info vortex.zarr

  chronocl verify vortex.zarr

  chronocl integrate vortex.zarr alpha.zarr --mode alpha --window 0:30:10

  chronocl render jet.zarr -o trio.png --mode alpha,additive,max --window 0:30:14

  chronocl demo --out demo-out

  chronocl view vortex.zarr jet.zarr

  chronocl devices
""",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


@app.callback()
def _global_options(
    verbose: Annotated[
        bool,
        typer.Option("--verbose", help="Print details such as the OpenCL compiler's build log."),
    ] = False,
) -> None:
    """Options before the command, e.g. chronocl --verbose render ..."""
    if verbose:
        os.environ["CHRONOCL_VERBOSE"] = "1"


STORE_HINT = "create one with 'chronocl ingest' or 'chronocl generate'"


def _check_engine(engine: str) -> None:
    from chronocl.core.errors import UnknownNameError
    from chronocl.engine import ENGINES

    if engine not in ENGINES:
        raise UnknownNameError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")


# Options shared by `integrate` and `render`.
WindowOpt = Annotated[
    str | None, typer.Option(help="t0:t1[:stride] or a list 2,5,9 (default: all).")
]
OrderOpt = Annotated[str, typer.Option(help="forward, backward, or importance steps 9,2,5.")]
TfOpt = Annotated[Path | None, typer.Option(help="Transfer-function JSON (data_tf, time_tf).")]
TimeTfOpt = Annotated[
    str | None,
    typer.Option(help="Time TF preset: rgb, warm-cool, luminance, white, hat, inverted-hat."),
]
ThresholdOpt = Annotated[float, typer.Option(help="first_hit opacity threshold.")]
NormalizeOpt = Annotated[str, typer.Option(help="additive normalisation: time or max.")]
EngineOpt = Annotated[str, typer.Option(help="opencl (default) or numpy (the reference).")]
DeviceOpt = Annotated[
    str | None,
    typer.Option(help="OpenCL device: index 0:1 or a name part (see 'chronocl devices')."),
]


def _parse_sizes(text: str, n: int, form: str, example: str) -> tuple[int, ...]:
    """n positive integers written AxB[xC], e.g. 64x64x64."""
    try:
        parts = tuple(int(p) for p in text.lower().split("x"))
    except ValueError:
        parts = ()
    if len(parts) != n or min(parts) < 1:
        raise InvalidParameterError(f"{text!r} must be {form} with positive sizes, e.g. {example}")
    return parts


MAX_GENERATED_STEPS = 100_000
MAX_GENERATED_SIDE = 4096
MAX_GENERATED_VOXELS = 2**30  # 4 GiB of float32 per step, computed in memory


@app.command()
def generate(
    name: Annotated[str, typer.Argument(help="Data set: vortex or jet.")],
    out_path: Annotated[Path, typer.Argument(metavar="OUT.zarr", help="Store to write.")],
    shape: Annotated[str, typer.Option(help="Volume size NXxNYxNZ.")] = "64x64x64",
    steps: Annotated[int, typer.Option(help="Number of time steps.")] = 30,
    seed: Annotated[int, typer.Option(help="Seed of the smooth random variations.")] = 0,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Write a built-in synthetic time-varying data set.

    Example: chronocl generate jet jet.zarr --shape 96x64x64 --steps 20
    """
    from chronocl.core.paths import check_target
    from chronocl.data import synthetic
    from chronocl.data.series import write_series

    nx, ny, nz = _parse_sizes(shape, 3, "NXxNYxNZ", "64x64x64")
    if name not in synthetic.DATASETS:
        synthetic.step(name, 0, 1, (1, 1, 1))  # raises the unknown-name error
    if not 1 <= steps <= MAX_GENERATED_STEPS:
        raise InvalidParameterError(
            f"--steps is {steps}; generate 1 to {MAX_GENERATED_STEPS} steps"
        )
    if max(nx, ny, nz) > MAX_GENERATED_SIDE or nx * ny * nz > MAX_GENERATED_VOXELS:
        raise InvalidParameterError(
            f"--shape {nx}x{ny}x{nz} is too large to generate; use at most "
            f"{MAX_GENERATED_SIDE} per side and {MAX_GENERATED_VOXELS // 2**20} Mi voxels, "
            "e.g. --shape 256x256x256"
        )
    check_target(out_path, overwrite)
    t0 = time.perf_counter()
    series = write_series(
        out_path,
        synthetic.steps(name, steps, (nz, ny, nx), seed),
        n_steps=steps,
        volume_shape=(nz, ny, nx),
        dtype="float32",
        source=f"chronocl generate {name} --shape {nx}x{ny}x{nz} --steps {steps} --seed {seed}",
        overwrite=overwrite,
        progress=True,
    )
    err.print(f"wrote {out_path} in {time.perf_counter() - t0:.1f} s")
    _print_summary(series.describe())


@app.command()
def ingest(
    inputs: Annotated[
        list[str],
        typer.Argument(
            help="Raw files or globs (one per step), a .npy (T, Z, Y, X), a NetCDF/HDF5 file, "
            "TIFF stacks (one per step, or one 4D TZYX), or an OME-Zarr folder."
        ),
    ],
    out_path: Annotated[
        Path, typer.Option("--out", "-o", metavar="OUT.zarr", help="Store to write.")
    ],
    fmt: Annotated[
        str,
        typer.Option("--format", help="auto (by file type), raw, npy, netcdf, tiff, omezarr."),
    ] = "auto",
    dims: Annotated[
        tuple[int, int, int] | None,
        typer.Option(metavar="NX NY NZ", help="Raw: volume size, x fastest."),
    ] = None,
    dtype: Annotated[
        str, typer.Option(help="Raw: float32, uint8, uint16, int16, float64.")
    ] = "float32",
    endian: Annotated[str, typer.Option(help="Raw: little or big.")] = "little",
    var: Annotated[str | None, typer.Option(help="NetCDF/HDF5: the variable.")] = None,
    time_dim: Annotated[str | None, typer.Option(help="NetCDF/HDF5: the time dimension.")] = None,
    dims_order: Annotated[
        str | None,
        typer.Option(help="NetCDF/HDF5: dimension names for t,z,y,x, e.g. time,lev,lat,lon."),
    ] = None,
    channel: Annotated[int, typer.Option(help="OME-Zarr: channel index.")] = 0,
    level: Annotated[int, typer.Option(help="OME-Zarr: resolution level (0 = full).")] = 0,
    spacing: Annotated[
        tuple[float, float, float] | None,
        typer.Option(metavar="DX DY DZ", help="Raw/npy/TIFF: voxel spacing."),
    ] = None,
    nan_fill: Annotated[
        float | None, typer.Option(help="Replace NaN/Inf with this value (default: reject them).")
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Convert time steps into a chronocl store (zarr v3), with statistics.

    Files are sorted naturally (step2 before step10). The store appears only when complete.

    Examples:

      chronocl ingest 'vortex/*.raw' -o vortex.zarr --dims 128 128 128

      chronocl ingest a.raw b.raw -o ab.zarr --dims 64 64 32 --dtype uint16 --endian big

      chronocl ingest series.npy -o series.zarr --spacing 1 1 2.5

      chronocl ingest ocean.nc -o ocean.zarr --var temp --time-dim time

      chronocl ingest 'cells/t*.tif' -o cells.zarr

      chronocl ingest embryo.ome.zarr -o embryo.zarr --channel 1 --level 0
    """
    from chronocl.core.paths import GLOB_CHARS, check_input, check_target
    from chronocl.data.ingest import ingest as run_ingest

    for item in inputs:
        if not GLOB_CHARS & set(item):
            check_input(item, "input", hint="check the path, or quote a glob such as 'v_*.raw'")
    check_target(out_path, overwrite, inputs)
    options: dict = {"nan_fill": nan_fill, "overwrite": overwrite, "progress": True}
    if dims is not None:
        options["dims"] = dims
    for key, value, default in (
        ("dtype", dtype, "float32"),
        ("endian", endian, "little"),
        ("channel", channel, 0),
        ("level", level, 0),
    ):
        if value != default:
            options[key] = value
    if var is not None:
        options["var"] = var
    if time_dim is not None:
        options["time_dim"] = time_dim
    if dims_order is not None:
        options["dims_order"] = [d.strip() for d in dims_order.split(",")]
    if spacing is not None:
        options["spacing"] = (spacing[2], spacing[1], spacing[0])
    t0 = time.perf_counter()
    series = run_ingest(inputs, out_path, fmt, **options)
    err.print(f"wrote {out_path} in {time.perf_counter() - t0:.1f} s")
    _print_summary(series.describe())


@app.command()
def info(
    store: Annotated[Path, typer.Argument(help="A chronocl series or chronovolume store.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Show shape, dtype, value range, steps, chunking and size on disk.

    Example: chronocl info vortex.zarr --json
    """
    from chronocl.core.errors import StoreFormatError
    from chronocl.core.paths import check_input
    from chronocl.data.chronovolume import Chronovolume
    from chronocl.data.series import open_series

    check_input(store, "store", hint=STORE_HINT)
    try:
        summary = open_series(store).describe()
    except StoreFormatError:
        cv = Chronovolume.load(store)
        summary = {"chronovolume": str(store), "shape (Z, Y, X)": list(cv.shape), **cv.metadata}
    if as_json:
        out.print_json(json.dumps(summary, default=str))
    else:
        _print_summary(summary)


@app.command()
def integrate(
    store: Annotated[Path, typer.Argument(help="Series store.")],
    out_path: Annotated[
        Path,
        typer.Argument(
            metavar="OUT",
            help="Chronovolume to write: .zarr, .ome.zarr (napari) or .vti (ParaView).",
        ),
    ],
    mode: Annotated[str, typer.Option(help="alpha, first_hit, additive, max or min.")] = "alpha",
    window: WindowOpt = None,
    order: OrderOpt = "forward",
    tf: TfOpt = None,
    time_tf: TimeTfOpt = None,
    enhance: Annotated[str, typer.Option(help="none, edge or silhouette.")] = "none",
    threshold: ThresholdOpt = 0.0,
    normalize: NormalizeOpt = "time",
    engine: EngineOpt = "opencl",
    device: DeviceOpt = None,
    memory: Annotated[
        str,
        typer.Option(help="Memory budget; larger windows stream z-slabs into a .zarr OUT."),
    ] = "2GB",
    scheduler: Annotated[
        str | None,
        typer.Option(help="dask scheduler address (tcp://host:8786): one task per z-slab."),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(help="Start a local dask cluster of N worker processes (spawned)."),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Integrate a window of time steps into a chronovolume store.

    A window too large for --memory is streamed slab by slab into a .zarr OUT; with
    --scheduler or --workers the slabs run on a dask cluster. An interrupted streamed run
    resumes when run again with the same arguments.

    Examples:

      chronocl integrate vortex.zarr a.zarr --mode alpha --window 0:30:10

      chronocl integrate jet.zarr m.zarr --mode max --window 0:10 --order backward

      chronocl integrate big.zarr a.zarr --memory 4GB --workers 2
    """
    from chronocl.core.budget import parse_memory
    from chronocl.core.paths import check_input, check_target
    from chronocl.data.formats.outputs import output_kind, save_chronovolume
    from chronocl.data.series import open_series
    from chronocl.integration.inmemory import integrate as run
    from chronocl.integration.inmemory import prepare
    from chronocl.integration.streaming import fits_in_memory

    # Everything is checked before any work: no kernel built, no brick read, nothing written.
    kind = output_kind(out_path)
    budget = parse_memory(memory)
    _check_engine(engine)
    if workers is not None and workers < 1:
        raise InvalidParameterError(f"--workers is {workers}; start at least 1 worker")
    if scheduler is not None:
        _check_scheduler(scheduler, workers)
    check_input(store, "store", hint=STORE_HINT)
    spec_args = _spec_args(tf, time_tf, order, enhance, threshold, normalize)
    check_target(out_path, overwrite, [store, tf])
    series = open_series(store)
    t0 = time.perf_counter()
    job = prepare(series, window, mode, None, spec_args)
    if scheduler or workers or not fits_in_memory(job, budget, engine):
        if kind != ".zarr" and not (scheduler or workers):
            raise InvalidParameterError(
                f"this window needs more than --memory {memory} in memory; write a .zarr "
                "OUT (streamed slab by slab) and convert it, or give a larger --memory"
            )
        _integrate_streaming(
            series,
            window,
            out_path,
            scheduler,
            workers,
            mode=mode,
            memory=budget,
            engine=engine,
            device=device,
            overwrite=overwrite,
            **spec_args,
        )
        err.print(f"wrote {out_path} ({mode}, streamed) in {time.perf_counter() - t0:.2f} s")
        return
    cv = run(series, window, mode, engine=engine, device=device, progress=True, **spec_args)
    save_chronovolume(cv, out_path, overwrite=overwrite)
    err.print(f"wrote {out_path} ({mode}, steps {cv.steps}) in {time.perf_counter() - t0:.2f} s")


def _check_scheduler(address: str, workers: int | None) -> None:
    """A dask scheduler address: [scheme://]host:port."""
    from urllib.parse import urlsplit

    if workers is not None:
        raise InvalidParameterError("give either --scheduler ADDRESS or --workers N, not both")
    try:
        parts = urlsplit(address if "://" in address else f"tcp://{address}")
        ok = bool(parts.hostname) and parts.port is not None and parts.port > 0
    except ValueError:  # a port that is not a number or out of range
        ok = False
    if not ok:
        raise InvalidParameterError(
            f"--scheduler {address!r} is not a scheduler address; write it like "
            "tcp://host:8786 (host and port)"
        )


def _integrate_streaming(series, window, out_path, scheduler, workers, **args) -> None:
    """integrate_to_store(**args) locally, or on a dask cluster; resume notes go to stderr."""
    import logging

    from chronocl.integration.streaming import integrate_to_store

    log = logging.getLogger("chronocl")
    if not log.handlers:
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("chronocl: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
    if not (scheduler or workers):
        integrate_to_store(series, window, out_path, progress=True, **args)
        return
    from chronocl.integration.distributed import connect, dashboard_link

    with connect(scheduler, workers) as client:
        link = dashboard_link(client)
        if link:
            err.print(f"dask dashboard: {link}", highlight=False)
        integrate_to_store(series, window, out_path, client=client, progress=True, **args)


def _parse_floats(text: str, n: int, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != n:
        raise InvalidParameterError(f"{what} {text!r} must be {n} comma-separated numbers")
    return values


def _spec_args(tf, time_tf, order, enhance, threshold, normalize) -> dict:
    """The integration options that integrate and render share, with the TF file loaded."""
    from chronocl.core.tf import TFSetting

    return dict(
        tf=TFSetting.load(tf) if tf is not None else None,
        time_tf=time_tf,
        order=_parse_order(order),
        enhance=enhance,
        threshold=threshold,
        normalize=normalize,
    )


def _parse_order(order: str) -> str | list[int]:
    if order in ("forward", "backward"):
        return order
    try:
        return [int(s) for s in order.split(",")]
    except ValueError:
        return order  # the spec names the problem


@app.command()
def render(
    store: Annotated[Path, typer.Argument(help="Series store.")],
    out_path: Annotated[
        Path, typer.Option("--out", "-o", metavar="OUT.png", help="Image to write.")
    ],
    mode: Annotated[
        list[str], typer.Option(help="Mode(s); repeat or comma-separate for parallel views.")
    ] = ["alpha"],  # noqa: B006
    window: WindowOpt = None,
    order: OrderOpt = "forward",
    tf: TfOpt = None,
    time_tf: TimeTfOpt = None,
    enhance: Annotated[
        str, typer.Option(help="none, edge or silhouette (follows the camera).")
    ] = "none",
    threshold: ThresholdOpt = 0.0,
    normalize: NormalizeOpt = "time",
    azimuth: Annotated[float, typer.Option(help="Degrees around the vertical axis.")] = 30.0,
    elevation: Annotated[float, typer.Option(help="Degrees above the horizon.")] = 20.0,
    zoom: Annotated[float, typer.Option(help="Magnification (1 fits the volume).")] = 1.0,
    projection: Annotated[str, typer.Option(help="perspective or orthographic.")] = "perspective",
    size: Annotated[str, typer.Option(help="Image (panel) size WxH, 16..8192.")] = "512x512",
    clip: Annotated[
        str | None,
        typer.Option(help="Slicing plane nx,ny,nz,offset (offset -1..1; keeps the normal's side)."),
    ] = None,
    background: Annotated[str, typer.Option(help="Colour name or #rrggbb.")] = "black",
    outline: Annotated[bool, typer.Option(help="Draw the volume's bounding box.")] = False,
    engine: EngineOpt = "opencl",
    device: DeviceOpt = None,
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
) -> None:
    """Integrate a window and render it; several modes become parallel views in one image.

    Examples:

      chronocl render vortex.zarr -o alpha.png --mode alpha --window 0:20:9

      chronocl render jet.zarr -o trio.png --mode alpha,additive,max --window 0:30:14

      chronocl render vortex.zarr -o cut.png --clip 1,0,0,0 --azimuth 60 --zoom 1.4

      chronocl render vortex.zarr -o s.png --enhance silhouette --turntable s.mp4
    """
    from chronocl.core.enhance import Enhance
    from chronocl.core.paths import check_distinct, check_input, check_target
    from chronocl.data.formats.outputs import output_kind
    from chronocl.data.formats.outputs import save_chronovolume as save_any
    from chronocl.data.series import open_series
    from chronocl.integration.inmemory import integrate as run
    from chronocl.integration.inmemory import prepare
    from chronocl.render import Camera, render_views
    from chronocl.render.raycaster import check_clip, check_size
    from chronocl.render.turntable import check_video
    from chronocl.render.turntable import turntable as make_turntable
    from chronocl.render.views import parse_color, raycaster

    # Every option is checked before any work: no kernel built, no brick read, nothing written.
    modes = [m.strip() for item in mode for m in item.split(",") if m.strip()]
    if not modes:
        raise InvalidParameterError("--mode names no mode; give e.g. --mode alpha,max")
    if len(set(modes)) < len(modes):
        twice = next(m for m in modes if modes.count(m) > 1)
        raise InvalidParameterError(f"--mode {twice} is given twice; name each mode once")
    _check_engine(engine)
    camera = Camera(azimuth, elevation, zoom, projection=projection)
    panel = check_size(_parse_sizes(size, 2, "WxH", "512x512"))
    parse_color(background)
    clip_plane = check_clip(_parse_floats(clip, 4, "clip")) if clip else None
    if turntable is not None:
        check_video(turntable, frames)
    elif not 2 <= frames <= 3600:
        raise InvalidParameterError(f"turntable frames is {frames}; use 2 to 3600")
    Enhance(enhance)  # an unknown kind fails here
    saves = _chronovolume_paths(save_chronovolume, modes)
    for path in saves:
        output_kind(path)
    check_input(store, "store", hint=STORE_HINT)
    spec_args = _spec_args(tf, time_tf, order, enhance, threshold, normalize)
    outputs = [out_path, *([turntable] if turntable is not None else []), *saves]
    check_distinct(outputs)
    for path in outputs:
        check_target(path, overwrite, [store, tf])
    series = open_series(store)
    for m in modes:  # window, modes, order, transfer functions, normalisation, threshold
        prepare(series, window, m, None, spec_args)

    def chronovolumes(cam: Camera):
        view = cam.view_direction()
        args = dict(spec_args, engine=engine, device=device)
        if enhance == "silhouette":
            args["enhance"] = Enhance(enhance, view=view)
        return [run(series, window, m, **args) for m in modes]

    t0 = time.perf_counter()
    cvs = chronovolumes(camera)
    t1 = time.perf_counter()

    def frame(cam: Camera, cvs=cvs, volumes=None):
        if enhance == "silhouette" and cam is not camera:
            cvs = chronovolumes(cam)  # the silhouette depends on the view: re-integrate
            volumes = None
        return render_views(
            cvs,
            cam,
            panel,
            background=background,
            clip=clip_plane,
            outline=outline,
            legend=True,
            labels=None if len(cvs) > 1 else [],
            volumes=volumes,
        )

    image = frame(camera)
    image.save(out_path, overwrite=overwrite)
    err.print(
        f"wrote {out_path} ({', '.join(modes)}; integrate {t1 - t0:.2f} s, "
        f"render {time.perf_counter() - t1:.2f} s)"
    )
    for cv, path in zip(cvs, saves, strict=False):
        save_any(cv, path, overwrite=overwrite)
        err.print(f"wrote {path}")
    if turntable is not None:
        # Without silhouettes every frame shows the same chronovolumes: upload them once.
        volumes = [] if enhance == "silhouette" else [raycaster().upload(cv) for cv in cvs]
        try:
            make_turntable(
                lambda cam: frame(cam, volumes=volumes or None),
                camera,
                turntable,
                frames=frames,
                overwrite=overwrite,
                progress=True,
            )
        finally:
            for volume in volumes:
                volume.release()
        err.print(f"wrote {turntable} ({frames} frames)")


def _chronovolume_paths(path: Path | None, modes: list[str]) -> list[Path]:
    """One path per mode: NAME-MODE.SUFFIX when there are several (.ome.zarr kept whole)."""
    if path is None:
        return []
    if len(modes) == 1:
        return [path]
    name = path.name
    suffix = ".ome.zarr" if name.lower().endswith(".ome.zarr") else path.suffix
    stem = name[: len(name) - len(suffix)] if suffix else name
    return [path.with_name(f"{stem}-{m}{suffix}") for m in modes]


@app.command()
def export(
    store: Annotated[Path, typer.Argument(help="Series store.")],
    out_path: Annotated[
        Path, typer.Option("--out", "-o", metavar="OUT", help="Folder (vti, raw) or .npy file.")
    ],
    fmt: Annotated[str, typer.Option("--format", help="vti, npy or raw.")] = "vti",
    window: WindowOpt = None,
    z: Annotated[str | None, typer.Option(help="Only rows z0:z1 of every step.")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
) -> None:
    """Export time steps of a series: .vti per step with a .pvd (ParaView), .npy, or raw files.

    Examples:

      chronocl export vortex.zarr -o vortex-vti --format vti --window 0:30:5

      chronocl export vortex.zarr -o slab.npy --format npy --window 0:10 --z 40:60

      chronocl export vortex.zarr -o raw-steps --format raw
    """
    from chronocl.core.paths import check_input
    from chronocl.data.formats.export import export_series
    from chronocl.data.series import open_series

    check_input(store, "store", hint=STORE_HINT)
    paths = export_series(  # which refuses an output onto, into or around the store
        open_series(store),
        out_path,
        fmt=fmt,
        window=window,
        z=z,
        overwrite=overwrite,
        progress=True,
    )
    err.print(f"wrote {len(paths)} file(s) under {out_path}")


@app.command()
def view(
    stores: Annotated[list[Path], typer.Argument(help="Series store(s) to offer in the viewer.")],
    host: Annotated[
        str, typer.Option(help="Interface to listen on; other than 127.0.0.1 exposes the data.")
    ] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port to listen on (0: a free one).")] = 0,
    browser: Annotated[
        bool, typer.Option("--browser/--no-browser", help="Open the page in a browser.")
    ] = True,
    engine: EngineOpt = "opencl",
    device: DeviceOpt = None,
    memory: Annotated[
        str | None, typer.Option(help="Memory budget of each view's window (e.g. 2GB).")
    ] = None,
    max_clients: Annotated[
        int, typer.Option(help="Most browser connections served at once (each has a thread).")
    ] = 32,
) -> None:
    """Interactive viewer in the browser, rendered here (OpenCL + EGL) and streamed as frames.

    Prints http://127.0.0.1:PORT/?token=TOKEN: the page, its assets and its socket all need
    the token, and the Host header must name this server. From another machine, forward the
    port: ssh -L PORT:127.0.0.1:PORT host. Every option is checked before the server starts.

    Examples:

      chronocl view vortex.zarr jet.zarr

      chronocl view vortex.zarr --port 8765 --no-browser
    """
    from chronocl.viewer import serve

    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as exc:
        raise InvalidParameterError(
            f"the viewer needs {exc.name}; pip install 'starlette' 'uvicorn[standard]'"
        ) from None
    serve(
        stores,
        host=host,
        port=port,
        open_browser=browser,
        engine=engine,
        device=device,
        memory=memory,
        max_clients=max_clients,
    )


@app.command()
def verify(
    store: Annotated[Path, typer.Argument(help="A chronocl series or chronovolume store.")],
) -> None:
    """Read a whole store back: every chunk must decode and every step match its statistics.

    Exits 0 when the store is sound, 2 with one line naming the first damage otherwise.

    Example: chronocl verify vortex.zarr
    """
    from chronocl.core.paths import check_input
    from chronocl.data.verify import verify as run_verify

    check_input(store, "store", hint=STORE_HINT)
    _print_summary(run_verify(store, progress=True))


@app.command()
def devices() -> None:
    """List the OpenCL platforms and devices, marking the default one.

    Select one with --device 0:1 (platform:device), a part of its name, or CHRONOCL_DEVICE.

    Example: chronocl devices
    """
    from chronocl.engine.device import NO_PLATFORM, list_devices, pick_device

    found = list_devices()
    if not found:
        err.print(f"chronocl: {NO_PLATFORM}", highlight=False, markup=False)
        return
    default = pick_device(None)[0].index
    for d in found:
        mark = "*" if d.index == default else " "
        out.print(
            f"{mark} {d.index}  {d.kind:<4} {d.label}  ({d.version}; driver {d.driver}; "
            f"{d.compute_units} compute units, {d.global_mem / 2**30:.1f} GiB)",
            highlight=False,
        )


@app.command()
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo outputs.")] = Path(
        "demo-out"
    ),
) -> None:
    """Generate the built-in data sets, integrate every mode, and print summaries.

    Example: chronocl demo --out demo-out
    """
    from chronocl.demo import run_demo

    run_demo(out_dir)


def _print_summary(summary: dict) -> None:
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        out.print(f"{key:<{width}}  {value}", highlight=False, soft_wrap=True)


def main() -> None:
    """Console entry point: run the app, turning chronocl errors into one line and exit 2.

    Usage errors (missing or malformed options) are typer's own: usage, one line, exit 2.
    An OSError that escaped the checks made before the work (a folder made read-only
    meanwhile, a full disk) is one line naming the path, exit 2.
    """
    try:
        app()
    except ChronoclError as exc:
        _fail(str(exc), exc.exit_code)
    except OSError as exc:
        _fail(_os_error_line(exc), 2)


def _fail(message: str, code: int) -> None:
    line = " ".join(message.splitlines())  # one line, whatever the message held
    err.print(f"chronocl: error: {line}", highlight=False, markup=False, soft_wrap=True)
    sys.exit(code)


def _os_error_line(exc: OSError) -> str:
    """'<reason>: <path>; <fix>' for an OSError."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    path = exc.filename if exc.filename is not None else ""
    where = f" {os.fspath(path)!r}" if path != "" else ""
    if exc.errno == errno.ENOSPC:
        fix = "free some disk space or write the output elsewhere"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = "choose a location you can write, or fix its permissions"
    elif exc.errno == errno.ENOTDIR:
        fix = "a part of the path is a file, not a folder; fix the path"
    elif exc.errno == errno.ENOENT:
        fix = "check that the path exists"
    else:
        fix = "check the path"
    return f"{reason}:{where}; {fix}"


if __name__ == "__main__":
    main()
