"""`chronocl view`: serve the interactive browser viewer of one or more series stores."""

from __future__ import annotations

import logging
import sys
from typing import Annotated

import typer

from chronocl.cli.options import AnonOpt, DeviceOpt, EngineOpt, StorageOpt
from chronocl.core.errors import InvalidParameterError
from chronocl.viewer.protocol import LIMITS


def view(
    stores: Annotated[
        list[str],
        typer.Argument(help="Series store(s) to offer: paths, or http(s):// or s3:// URLs."),
    ],
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
        str | None,
        typer.Option(
            help="Memory limit of the viewer process, every client's steps and frames, "
            "e.g. 8GB (default: half the memory free, at least 2GB)."
        ),
    ] = None,
    max_clients: Annotated[
        int, typer.Option(help="Most browser connections served at once (each has a thread).")
    ] = LIMITS.clients,
    anon: AnonOpt = False,
    storage_option: StorageOpt = None,
    log_level: Annotated[
        str,
        typer.Option(
            "--log-level",
            help="What the server logs on stderr: warning (default: warnings, and internal "
            "errors with their tracebacks), info, or debug (everything the chronocl loggers "
            "say).",
        ),
    ] = "warning",
) -> None:
    """Interactive viewer in the browser, rendered here (OpenCL + EGL) and streamed as frames.

    Prints http://127.0.0.1:PORT/?token=TOKEN: the page, its assets and its socket all need
    the token, and the Host header must name this server. From another machine, forward the
    port: ssh -L PORT:127.0.0.1:PORT host. Every option is checked before the server starts.

    Examples:

      chronocl view vortex.zarr jet.zarr

      chronocl view vortex.zarr --port 8765 --no-browser

      chronocl view s3://open-data/plume.zarr --anon

      chronocl view vortex.zarr --log-level debug
    """
    level = log_levels(log_level)
    from chronocl.viewer import serve

    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as exc:
        raise InvalidParameterError(
            f"the viewer needs {exc.name}; pip install 'starlette' 'uvicorn[standard]'"
        ) from None
    from chronocl.data.remote import is_url, parse_storage_options

    if (anon or storage_option) and not any(is_url(s) for s in stores):
        raise InvalidParameterError(
            "--anon and --storage-option apply to http(s):// and s3:// stores; none was given"
        )
    configure_logging(level)
    serve(
        stores,
        host=host,
        port=port,
        open_browser=browser,
        engine=engine,
        device=device,
        memory=memory,
        max_clients=max_clients,
        storage_options=parse_storage_options(storage_option, anon),
    )


LOG_LEVELS = {"warning": logging.WARNING, "info": logging.INFO, "debug": logging.DEBUG}


def log_levels(name: str) -> int:
    """The logging level `--log-level` names (warning, info, debug; any case)."""
    level = LOG_LEVELS.get(name.strip().lower())
    if level is None:
        raise InvalidParameterError(
            f"--log-level {name!r} is not a level; choose one of {', '.join(LOG_LEVELS)}"
        )
    return level


def configure_logging(level: int) -> None:
    """The `chronocl` loggers' records at `level` and above written to stderr by one handler
    of ours (replaced, not added again, when called twice). At warning each record is its
    message (its traceback under it), as Python printed them with no handler; at info and
    debug, with the time, level and logger before it, as there are many."""
    log = logging.getLogger("chronocl")
    for h in [h for h in log.handlers if getattr(h, "chronocl_cli", False)]:
        log.removeHandler(h)
    handler = logging.StreamHandler(sys.stderr)
    handler.chronocl_cli = True  # type: ignore[attr-defined]
    fmt = (
        "%(message)s"
        if level >= logging.WARNING
        else "%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    handler.setFormatter(logging.Formatter(fmt))
    log.addHandler(handler)
    log.setLevel(level)
