"""`chronocl ingest`: convert raw, npy, NetCDF/HDF5, TIFF or OME-Zarr time steps into a store."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from chronocl.cli.options import err, print_summary


def ingest(
    out_path: Annotated[
        str,
        typer.Option(
            "--out",
            "-o",
            metavar="OUT.zarr",
            help="Store to write: a path, or an s3:// URL (published whole, root metadata last).",
        ),
    ],
    inputs: Annotated[
        list[str] | None,
        typer.Argument(
            metavar="INPUTS",
            help="Raw files or globs (one per step), a .npy (T, Z, Y, X), a NetCDF/HDF5 file, "
            "TIFF stacks (one per step, or one 4D TZYX), or an OME-Zarr folder; none with "
            "--magnitude U,V,W naming raw/npy/TIFF inputs.",
        ),
    ] = None,
    fmt: Annotated[
        str,
        typer.Option("--format", help="auto (by file type), raw, npy, netcdf, tiff, omezarr."),
    ] = "auto",
    dims: Annotated[
        tuple[int, int, int] | None,
        typer.Option(metavar="NX NY NZ", help="Raw: volume size, x fastest."),
    ] = None,
    dtype: Annotated[
        str | None,
        typer.Option(help="Raw: float32 (default), uint8, uint16, int16, float64."),
    ] = None,
    endian: Annotated[str | None, typer.Option(help="Raw: little (default) or big.")] = None,
    var: Annotated[str | None, typer.Option(help="NetCDF/HDF5: the variable.")] = None,
    variables: Annotated[
        list[str] | None,
        typer.Option(
            metavar="A,B",
            help="NetCDF/HDF5: several variables, OME-Zarr: several channels (by label, or "
            "'all'), each a series of one store (open one with "
            "chronocl.open(store).variable(name)); comma-separate or repeat.",
        ),
    ] = None,
    magnitude: Annotated[
        str | None,
        typer.Option(
            metavar="U,V,W",
            help="Store the magnitude sqrt(u²+v²+w²) (float32) of two or three components: "
            "NetCDF/HDF5 variables, or, with no other inputs, raw/npy/TIFF inputs (globs).",
        ),
    ] = None,
    resample: Annotated[
        str | None,
        typer.Option(
            metavar="uniform",
            help="NetCDF/HDF5: interpolate a non-uniformly spaced z/y/x coordinate linearly "
            "onto uniform spacing (without it such a file is refused).",
        ),
    ] = None,
    time_dim: Annotated[str | None, typer.Option(help="NetCDF/HDF5: the time dimension.")] = None,
    dims_order: Annotated[
        str | None,
        typer.Option(help="NetCDF/HDF5: dimension names for t,z,y,x, e.g. time,lev,lat,lon."),
    ] = None,
    channel: Annotated[int, typer.Option(help="OME-Zarr: channel index.")] = 0,
    level: Annotated[int, typer.Option(help="OME-Zarr: resolution level (0 = full).")] = 0,
    spacing: Annotated[
        tuple[float, float, float] | None,
        typer.Option(
            metavar="DX DY DZ",
            help="Raw/npy/TIFF: voxel spacing, x first (as TimeSeries.from_array(spacing=...)).",
        ),
    ] = None,
    times: Annotated[
        str | None,
        typer.Option(
            metavar="TIMES",
            help="Raw/npy/TIFF: the physical time of each step, shown by legends, captions, the "
            "viewer and probe plots: a comma list (0,0.5,1), a file with one time per line, or "
            "FILE.json[:KEY] (e.g. meta.json:times, dots for nesting).",
        ),
    ] = None,
    times_from_meta: Annotated[
        Path | None,
        typer.Option(
            metavar="META.json",
            help="Raw/npy/TIFF: the steps' times from the JSON metadata a simulation wrote: a "
            "list under times/time/t/output_times, or a time step dt (with save_every or "
            "output_interval, and t0) from which each step's time is counted; its time_unit too.",
        ),
    ] = None,
    meta: Annotated[
        Path | None,
        typer.Option(
            metavar="META.json",
            help="The JSON a simulation wrote beside its output: dims, spacing, dtype, byte "
            "order and the steps' times (as --times-from-meta) where it gives them, for the "
            "inputs that take them; a flag given as well wins. Ingest says what it used.",
        ),
    ] = None,
    time_unit: Annotated[
        str | None,
        typer.Option(
            metavar="UNIT",
            help="The unit of the times (s, ms, min, h, days, ...), written after them in "
            "legends, captions, the viewer and probe plots; overrides the metadata's.",
        ),
    ] = None,
    nan_fill: Annotated[
        float | None, typer.Option(help="Replace NaN/Inf with this value (default: reject them).")
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    storage_option: Annotated[
        list[str] | None,
        typer.Option(
            "--storage-option",
            metavar="KEY=VALUE",
            help="s3fs option for an s3:// OUT, repeatable (endpoint_url=http://host:9000 for "
            "MinIO); values are read as JSON where they parse.",
        ),
    ] = None,
) -> None:
    """Convert time steps into a chronocl store (zarr v3), with statistics.

    Files are sorted naturally (step2 before step10). The store appears only when complete.

    Examples:

      chronocl ingest 'vortex/*.raw' -o vortex.zarr --dims 128 128 128

      chronocl ingest a.raw b.raw -o ab.zarr --dims 64 64 32 --dtype uint16 --endian big

      chronocl ingest series.npy -o series.zarr --spacing 1 1 2.5

      chronocl ingest 'plume/*.raw' -o plume.zarr --dims 64 96 56 --times plume/meta.json:t

      chronocl ingest series.npy -o series.zarr --times 0,0.25,0.5,0.75 --time-unit s

      chronocl ingest 'smoke/*.raw' -o smoke.zarr --dims 64 96 56 --times-from-meta smoke/run.json

      chronocl ingest 'smoke/*.raw' -o smoke.zarr --meta smoke/run.json

      chronocl ingest ocean.nc -o ocean.zarr --var temp --time-dim time

      chronocl ingest flow.nc -o speed.zarr --magnitude u,v,w

      chronocl ingest -o speed.zarr --magnitude 'u/*.raw,v/*.raw,w/*.raw' --dims 64 64 64

      chronocl ingest ocean.nc -o ocean.zarr --variables temp,salt --resample uniform

      chronocl ingest 'cells/t*.tif' -o cells.zarr

      chronocl ingest embryo.ome.zarr -o embryo.zarr --channel 1 --level 0

      chronocl ingest embryo.ome.zarr -o embryo.zarr --variables all

      chronocl ingest series.npy -o s3://bucket/series.zarr
    """
    from chronocl.core.errors import InvalidParameterError
    from chronocl.core.paths import GLOB_CHARS, check_input, check_target
    from chronocl.core.times_input import read_times, times_file
    from chronocl.core.times_meta import check_time_unit
    from chronocl.core.times_meta import times_from_meta as read_meta_times
    from chronocl.data.ingest import ingest as run_ingest
    from chronocl.data.remote import is_url, parse_storage_options
    from chronocl.data.remote_write import check_remote_output

    inputs = inputs or []
    named = magnitude.split(",") if magnitude and not inputs else []
    for item in [*inputs, *(n.strip() for n in named)]:
        if not GLOB_CHARS & set(item):
            check_input(item, "input", hint="check the path, or quote a glob such as 'v_*.raw'")
    out_options = parse_storage_options(storage_option)
    if is_url(out_path):
        check_remote_output(out_path, overwrite, out_options)  # before any work
        options: dict = {"storage_options": out_options}
    else:
        read = [meta, times_from_meta, times_file(times) if times is not None else None]
        check_target(Path(out_path), overwrite, [*inputs, *named, *read])
        if out_options:
            raise InvalidParameterError(
                f"--storage-option applies to an s3:// OUT, not to the local path {out_path!r}"
            )
        options = {}
    options.update(nan_fill=nan_fill, overwrite=overwrite, progress=True)
    for key, value, default in (  # only the options given: each reader refuses others
        ("dims", dims, None),
        ("dtype", dtype, None),
        ("endian", endian, None),
        ("channel", channel, 0),
        ("level", level, 0),
        ("var", var, None),
        ("magnitude", magnitude, None),
        ("resample", resample, None),
        ("time_dim", time_dim, None),
    ):
        if value != default:
            options[key] = value
    if variables:
        options["variables"] = [n for item in variables for n in item.split(",")]
    if dims_order is not None:
        options["dims_order"] = [d.strip() for d in dims_order.split(",")]
    if spacing is not None:
        options["spacing"] = spacing  # x first, as the Python API takes it
    found = None
    if times is not None and times_from_meta is not None:
        raise InvalidParameterError(
            "give --times or --times-from-meta, not both (--times FILE.json:KEY picks one list)"
        )
    if meta is not None and times_from_meta is not None:
        raise InvalidParameterError(
            "give --meta or --times-from-meta, not both (--meta reads the times too)"
        )
    used: list[str] = []  # what --meta gave, for the summary
    if meta is not None:
        found = _from_meta(meta, inputs, fmt, magnitude, options, times, time_unit, used)
    if times is not None:
        options["times"] = read_times(times)
    if times_from_meta is not None:
        found = read_meta_times(times_from_meta)
        options["times"] = found.times
        if found.unit and time_unit is None:  # --time-unit overrides the file's
            options["time_unit"] = found.unit_of()
    if time_unit is not None:
        if "times" not in options:
            raise InvalidParameterError(
                "--time-unit names the unit of the steps' times; give them with --times or "
                "--times-from-meta"
            )
        options["time_unit"] = check_time_unit(time_unit)
    flags = {}
    if found is not None:  # a reader that takes no times refuses the option that gave them
        flag = "--meta" if meta is not None else "--times-from-meta"
        flags = {"times": flag, "time_unit": flag}
        if time_unit is not None:
            flags["time_unit"] = "--time-unit"
    t0 = time.perf_counter()
    series = run_ingest(inputs, out_path, fmt, flags=flags, **options)
    for note in series.meta.get("resampled", []):
        err.print(f"note: {note}")
    err.print(f"wrote {out_path} in {time.perf_counter() - t0:.1f} s")
    for line in used:
        err.print(f"from --meta: {line}", highlight=False, soft_wrap=True)
    if found is not None:
        unit = f" {series.time_unit}" if series.time_unit else ""
        err.print(f"times: {series.times[0]} .. {series.times[-1]}{unit}, from {found.found}")
    if len(series.variables) > 1:
        err.print(f"variables: {', '.join(series.variables)}")
    print_summary(series.describe())


def _from_meta(meta: Path, inputs, fmt: str, magnitude, options: dict, times, time_unit, used):
    """Put what the metadata file gives into `options` where the reader takes it and no flag
    gave it (each noted in `used`); its times (a `MetaTimes`) where the reader takes times and
    none were given, else None; their unit unless --time-unit gave one."""
    from chronocl.data.formats.registry import READERS
    from chronocl.data.ingest import detect_format
    from chronocl.data.run_meta import read_run_meta

    named = magnitude.split(",")[:1] if magnitude and not inputs else inputs
    reader = READERS[fmt] if fmt in READERS else READERS[detect_format(named)] if named else None
    takes = set(reader.options) if reader is not None else set()
    given = {k for k in ("dims", "spacing", "dtype", "endian") if k in options or k not in takes}
    given |= {"times"} if times is not None or "times" not in takes else set()
    run = read_run_meta(meta, frozenset(given))
    for key, value in run.layout().items():
        options[key] = value
        shown = " ".join(map(str, value)) if isinstance(value, tuple) else value
        used.append(f"{key} {shown} ({run.found[key]})")
    if run.times is None:
        if not used:
            used.append(f"nothing: {meta} gives none of what this input takes from it")
        return None
    options["times"] = run.times.times
    if run.times.unit and time_unit is None:  # --time-unit overrides the file's
        options["time_unit"] = run.times.unit_of()
    return run.times
