"""The `chronocl` typer app: its help, the options before the command (--verbose), the commands
in the order the help lists them, and `main`, which turns chronocl's errors into one line.

Errors that chronocl raises on bad input print one line on stderr and exit with code 2,
never a traceback.
"""

from __future__ import annotations

import errno
import logging
import os
import sys
import warnings
from typing import Annotated

import typer

from chronocl.cli import (
    bench,
    demo,
    devices,
    events,
    export,
    generate,
    info,
    ingest,
    integrate,
    probe,
    pyramid,
    render,
    verify,
    view,
)
from chronocl.cli.options import err
from chronocl.core import env
from chronocl.core.errors import ChronoclError, ChronoclWarning

app = typer.Typer(
    name="chronocl",
    help="""Chronovolumes: integrate a window of time steps of a time-varying volume into one
RGBA volume through a temporal transfer function (Woodring & Shen 2003).

Examples:

  chronocl generate vortex vortex.zarr --shape 64x64x64 --steps 30

  chronocl ingest 'jet/jet_*.raw' -o jet.zarr --dims 128 128 128 --dtype float32

  chronocl info vortex.zarr

  chronocl verify vortex.zarr

  chronocl pyramid vortex.zarr

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
        env.set_value("CHRONOCL_VERBOSE", "1")


app.command()(generate.generate)
app.command()(ingest.ingest)
app.command()(info.info)
app.command(help=integrate.help_text())(integrate.integrate)
app.command()(render.render)
app.command()(export.export)
app.command()(probe.probe)
app.command()(events.events)
app.command()(view.view)
app.command()(verify.verify)
app.command()(pyramid.pyramid)
app.command()(devices.devices)
app.command()(bench.bench)
app.command()(demo.demo)


def main() -> None:
    """Console entry point: run the app, turning chronocl errors into one line and exit 2.

    Usage errors (missing or malformed options) are typer's own: usage, one line, exit 2.
    An OSError that escaped the checks made before the work (a folder made read-only
    meanwhile, a full disk) is one line naming the path, exit 2.
    """
    warnings.showwarning = _show_warning
    try:
        app()
    except ChronoclError as exc:
        _fail(str(exc), exc.exit_code)
    except OSError as exc:
        _fail(_os_error_line(exc), 2)


_python_showwarning = warnings.showwarning


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """chronocl's warnings as one line, 'chronocl: warning: ...'; others as Python shows them."""
    if issubclass(category, ChronoclWarning):
        text = " ".join(str(message).splitlines())
        err.print(f"chronocl: warning: {text}", highlight=False, markup=False, soft_wrap=True)
    else:
        _python_showwarning(message, category, filename, lineno, file, line)


def _fail(message: str, code: int) -> None:
    from chronocl.data.remote_store import settle

    line = " ".join(message.splitlines())  # one line, whatever the message held
    err.print(f"chronocl: error: {line}", highlight=False, markup=False, soft_wrap=True)
    # A remote store's reads given up with the command (its other chunk requests still pending
    # in zarr's event loop) are cancelled and unwound now; asyncio would log any left after the
    # error line (seen on Python 3.13 with a connection dropped mid-read).
    logging.getLogger("asyncio").setLevel(logging.CRITICAL + 1)
    settle()
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
