"""What the commands share: the consoles, the options of integrate and render, the parsers of
option values, and the listing of the registered modes for the help."""

from __future__ import annotations

import math
import textwrap
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from chronocl import modes
from chronocl.core.errors import InvalidParameterError

err = Console(stderr=True)
out = Console()

STORE_HINT = "create one with 'chronocl ingest' or 'chronocl generate'"

# Options shared by `integrate` and `render`.
WindowOpt = Annotated[
    str | None, typer.Option(help="t0:t1[:stride] or a list 2,5,9 (default: all).")
]
OrderOpt = Annotated[str, typer.Option(help="forward, backward, or importance steps 9,2,5.")]
TfOpt = Annotated[Path | None, typer.Option(help="Transfer-function JSON (data_tf, time_tf).")]
ColormapOpt = Annotated[
    str | None,
    typer.Option(
        help="Colour the data TF with a colour map (viridis, magma, inferno, cividis, grey, "
        "coolwarm, RdBu_r, turbo or any matplotlib name); its opacity curve is kept. Without "
        "--time-tf, time then shows as lightness (old dark, new bright) under the map's hue."
    ),
]
TimeTfOpt = Annotated[
    str | None,
    typer.Option(
        help="Time TF preset: rgb, warm-cool, lightness, luminance, white, hat, inverted-hat "
        "(default: rgb, or lightness with a coloured data TF such as --colormap)."
    ),
]
ThresholdOpt = Annotated[
    float | None,
    typer.Option(
        help="Opacity a step must exceed: first_hit's first hit, count's presence "
        "(default 0; count 0.25 under its own default TF)."
    ),
]
ValueRangeOpt = Annotated[
    str | None,
    typer.Option(
        metavar="window|series|LO,HI",
        help="What normalises the values for the data TF: window (fitted to the window's own "
        "values), series (the range recorded at ingest) or LO,HI (e.g. 0,2.5). Default: "
        "window, or the TF file's value_range. max/min's t_index does not depend on it.",
    ),
]
NormalizeOpt = Annotated[str, typer.Option(help="additive normalisation: time or max.")]
EngineOpt = Annotated[str, typer.Option(help="opencl (default) or numpy (the reference).")]
DeviceOpt = Annotated[
    str | None,
    typer.Option(help="OpenCL device: index 0:1 or a name part (see 'chronocl devices')."),
]
DeviceFormatOpt = Annotated[
    str,
    typer.Option(
        help="What bricks travel to the device in: auto (as stored), float32, float16, "
        "or uint8/uint16 quantised over the value range (lossy; docs/engine.md)."
    ),
]
TimeLabelsOpt = Annotated[
    str,
    typer.Option(
        help="What legends, captions and plots call a step: labels (the store's time labels, "
        "where it has them) or steps (step numbers)."
    ),
]
# Where a series store is read from: a local path, or an http(s):// or s3:// URL.
StoreArg = Annotated[
    str,
    typer.Argument(
        metavar="STORE",
        help="Series store: a path, or an http(s):// or s3:// URL read in place.",
    ),
]
AnonOpt = Annotated[
    bool,
    typer.Option("--anon", help="Read an s3:// store of a public bucket without credentials."),
]
StorageOpt = Annotated[
    list[str] | None,
    typer.Option(
        "--storage-option",
        metavar="KEY=VALUE",
        help="fsspec option for a remote STORE, repeatable (endpoint_url=http://host:9000 for "
        "MinIO, requester_pays=true); values are read as JSON where they parse.",
    ),
]

LevelOpt = Annotated[
    int,
    typer.Option(help="Coarse level to integrate (0: full resolution; see 'chronocl pyramid')."),
]

# Lighting of rendered views (chronocl/render/shading.py).
ShadingOpt = Annotated[
    bool,
    typer.Option(
        help="Light the volume from the camera by its opacity gradient (Blinn-Phong): "
        "depth and shape for single-colour regions. Off: flat colour."
    ),
]
ShadingParamsOpt = Annotated[
    str | None,
    typer.Option(
        metavar="A,D,S[,SHININESS]",
        help="Shading strengths ambient,diffuse,specular (0..2) and optionally the "
        "shininess (1..256); implies --shading. Default 0.3,0.7,0.3,24.",
    ),
]


def series_store(
    text: str | Path, anon: bool = False, storage_option: list[str] | None = None
) -> tuple[str | Path, dict]:
    """STORE and the storage options to open it with (`chronocl.open(store, storage_options=
    ...)`): a URL as it is, a local path checked to exist (options refused for it)."""
    from chronocl.core.paths import check_input
    from chronocl.data.remote import is_url, parse_storage_options, storage_options_for
    from chronocl.data.remote_store import check_url

    text = str(check_url(str(text)))  # a URL it cannot read: one line, before anything
    options = storage_options_for(text, parse_storage_options(storage_option, anon))
    if is_url(text):
        return text, options
    return check_input(text, "store", hint=STORE_HINT), options


def local_input(store: str | Path) -> Path | None:
    """`store` where it is a local path (an output must stay apart from it), else None."""
    return store if isinstance(store, Path) else None


def mode_choices() -> str:
    """The registered modes' names as a choice: 'alpha, first_hit, ... or min'."""
    names = modes.names()
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def modes_help(width: int = 76) -> str:
    """A help section listing every registered mode with its one-line summary."""
    names = modes.names()
    indent = max(len(n) for n in names) + 4
    lines = []
    for name in names:
        summary = textwrap.wrap(modes.get(name).summary, width - indent) or [""]
        lines.append(f"  {name:<{indent - 2}}{summary[0]}")
        lines += [" " * indent + rest for rest in summary[1:]]
    return "Modes:\n\n\b\n" + "\n".join(lines)


def parse_sizes(text: str, n: int, form: str, example: str) -> tuple[int, ...]:
    """n positive integers written AxB[xC], e.g. 64x64x64."""
    try:
        parts = tuple(int(p) for p in text.lower().split("x"))
    except ValueError:
        parts = ()
    if len(parts) != n or min(parts) < 1:
        raise InvalidParameterError(f"{text!r} must be {form} with positive sizes, e.g. {example}")
    return parts


def parse_floats(text: str, n: int, what: str) -> tuple[float, ...]:
    """n numbers written a,b,c."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != n:
        raise InvalidParameterError(f"{what} {text!r} must be {n} comma-separated numbers")
    return values


def spec_args(
    tf, time_tf, order, enhance, threshold, normalize, colormap=None, value_range=None
) -> dict:
    """The integration options that integrate and render share, with the TF file loaded and
    coloured by `colormap` if one is given (the time colours, unless --time-tf or the file
    gives them, then follow it: `chronocl.integration.inmemory.make_spec`), and --value-range
    (`make_spec`'s `value_range`)."""
    from chronocl.core.tf import TFSetting

    setting = TFSetting.load(tf) if tf is not None else None
    if colormap is not None:
        setting = setting or TFSetting()
        setting = replace(setting, data_tf=setting.data_tf.with_colormap(colormap))
    return dict(
        tf=setting,
        time_tf=time_tf,
        order=parse_order(order),
        enhance=enhance,
        threshold=threshold,
        normalize=normalize,
        value_range=None if value_range is None else parse_value_range(value_range),
    )


def parse_value_range(text: str) -> str | tuple[float, float]:
    """--value-range: "window", "series" (the data TF's "global") or two numbers LO,HI."""
    from numpy import float32

    from chronocl.core.tf import FITTED, GLOBAL  # "global" is the data TF's word for series

    word = text.strip().lower()
    if word in (FITTED, "series", GLOBAL):
        return FITTED if word == FITTED else "series"
    if "," not in text:
        raise InvalidParameterError(
            f"--value-range {text!r} is not window, series or LO,HI; e.g. --value-range 0,2.5"
        )
    lo, hi = parse_floats(text, 2, "--value-range LO,HI")
    if not (math.isfinite(lo) and math.isfinite(hi) and float32(hi) > float32(lo)):
        raise InvalidParameterError(
            f"--value-range {text} must be two finite numbers LO < HI (distinct in float32); "
            "e.g. --value-range 0,2.5"
        )
    return lo, hi


def range_words(jobs) -> str:
    """The value ranges jobs normalise by (one per mode where they differ) and where they came
    from, for the summary line."""
    text = {j.spec.mode: f"{j.value_range[0]:.4g} to {j.value_range[1]:.4g}" for j in jobs}
    kind = jobs[0].spec.data_tf.range_kind
    where = {"window": "fitted to the window", "global": "the series'"}.get(kind, "given")
    if len(set(text.values())) == 1:
        return f"value range {next(iter(text.values()))}, {where}"
    return "value range " + ", ".join(f"{m} {r}" for m, r in text.items()) + f", {where}"


def parse_order(order: str) -> str | list[int]:
    """forward, backward, or importance steps 9,2,5 as a list."""
    if order in ("forward", "backward"):
        return order
    try:
        return [int(s) for s in order.split(",")]
    except ValueError:
        return order  # the spec names the problem


def parse_shading(shading: bool, params: str | None):
    """The Shading of --shading and --shading-params (which implies --shading)."""
    from chronocl.render.shading import OFF, Shading

    if params is not None:
        return Shading.parse(params)
    return Shading() if shading else OFF


def print_summary(summary: dict) -> None:
    """key  value lines on stdout, the keys aligned."""
    width = max(len(k) for k in summary)
    for key, value in summary.items():
        out.print(f"{key:<{width}}  {value}", highlight=False, soft_wrap=True)
