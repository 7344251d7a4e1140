"""Kernel sources from `kernels/opencl/`, built once per (context, options) and cached.

Kernels live in files, shipped inside the wheel as `chronocl/kernels/`; in a
source checkout they are read from the top-level `kernels/`. A build failure
raises KernelBuildError naming the file, the options, the device and the
compiler log.

Builds are quiet: the compiler's log and pyopencl's CompilerWarning are captured, never
printed, unless CHRONOCL_VERBOSE=1 (the CLI's --verbose), which prints a non-empty log to
stderr after the file name, options and device. The kernels themselves build without
warnings on PoCL (tests/test_kernel_build.py), so clang has nothing to print either.
"""

from __future__ import annotations

import sys
import threading
import warnings
from functools import cache
from importlib import resources
from pathlib import Path

from chronocl.core import env
from chronocl.core.errors import KernelBuildError

RGBA8_H = "rgba8.h"  # after every header: the one rule by which kernels write RGBA8

_lock = threading.Lock()
_programs: dict[tuple, object] = {}
_kernels: dict[tuple, object] = {}


@cache
def kernel_dir() -> Path:
    """The folder holding the OpenCL sources (installed package first, then the checkout)."""
    packaged = Path(str(resources.files("chronocl"))) / "kernels" / "opencl"
    if packaged.is_dir():
        return packaged
    checkout = Path(__file__).resolve().parents[2] / "kernels" / "opencl"
    if checkout.is_dir():
        return checkout
    raise KernelBuildError(  # pragma: no cover - a broken install
        f"OpenCL kernels not found in {packaged} or {checkout}; reinstall chronocl"
    )


def source(name: str, common: bool | str = True) -> str:
    """kernels/opencl/NAME, after common.h unless `common` is false (a file name: after that
    header instead, e.g. the recolouring's recolour.h); rgba8.h follows the header, the one
    rule by which every kernel writes RGBA8."""
    folder = kernel_dir()
    text = (folder / name).read_text()
    header = "common.h" if common is True else common
    if not header:
        return text
    return "\n".join((folder / f).read_text() for f in (header, RGBA8_H)) + "\n" + text


def build_options(defines: dict[str, object]) -> tuple[str, ...]:
    """The -D options of `defines`: True gives -DKEY, False and None leave KEY undefined."""
    return tuple(
        f"-D{key}" if value is True else f"-D{key}={value}"
        for key, value in sorted(defines.items())
        if value is not False and value is not None
    )


def build(
    dc, name: str, defines: dict[str, object], text: str | None = None, common: bool | str = True
):
    """The built program for kernel file `name` with -D `defines` on device context `dc`.

    `text` replaces the file's source; `common` prepends common.h (or the header it names) to
    the file's source.
    """
    options = build_options(defines)
    key = (dc.info.index, str(kernel_dir()), name, options, text, common)
    with _lock:
        program = _programs.get(key)
        if program is None:
            src = text if text is not None else source(name, common)
            program = _compile(dc, name, src, options)
            _programs[key] = program
    return program


def verbose() -> bool:
    """Whether kernel build logs are shown (CHRONOCL_VERBOSE=1, set by the CLI's --verbose)."""
    return env.get("CHRONOCL_VERBOSE").lower() in ("1", "true", "yes", "on")


def _compile(dc, name: str, src: str, options: tuple[str, ...]):
    """Build `src` on `dc`, capturing the compiler's output (see the module docstring)."""
    import pyopencl as cl

    shown = " ".join(options) or "(none)"
    # catch_warnings swaps process-wide state; other threads' warnings caught meanwhile
    # are re-issued below, only pyopencl's CompilerWarning is kept back.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            program = cl.Program(dc.context, src).build(options=list(options))
        except cl.RuntimeError as exc:
            log = str(exc).strip().replace("\n", " | ")
            program = None
    compiler = []
    for w in caught:
        if issubclass(w.category, cl.CompilerWarning):
            compiler.append(str(w.message).strip())
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    if program is None:
        hint = ""
        if "unknown target CPU" in log:
            hint = (
                "; this OpenCL driver's LLVM does not know this CPU: pick another device "
                "('chronocl devices') or install Debian's PoCL ('apt-get install pocl-opencl-icd')"
            )
        raise KernelBuildError(
            f"building {name} failed on {dc.info.label} with options {shown}: {log}{hint}"
        )
    if verbose():
        text = _build_log(program) or "\n".join(compiler)
        if text:
            lines = "".join(f"  {line}\n" for line in text.splitlines())
            sys.stderr.write(
                f"chronocl: building {name} on {dc.info.label} with options {shown}:\n{lines}"
            )
            sys.stderr.flush()
    return program


def _build_log(program) -> str:
    """The program's build log on each of its devices, empty when the compiler said nothing."""
    import pyopencl as cl

    logs = []
    for device in program.devices:
        try:
            log = program.get_build_info(device, cl.program_build_info.LOG)
        except cl.Error:  # pragma: no cover - a driver that keeps no log
            continue
        if log and log.strip():
            logs.append(log.strip())
    return "\n".join(logs)


def kernel(dc, name: str, function: str, defines: dict[str, object], common: bool | str = True):
    """The cached kernel object `function` of kernel file `name` built with `defines`.

    Kernels carry their arguments, so callers set arguments and enqueue under the
    device context's lock.
    """
    import pyopencl as cl

    program = build(dc, name, defines, common=common)
    key = (id(program), function)
    with _lock:
        k = _kernels.get(key)
        if k is None:
            k = _kernels[key] = cl.Kernel(program, function)
    return k
