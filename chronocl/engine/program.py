"""Kernel sources from `kernels/opencl/`, built once per (context, options) and cached.

Kernels live in files, shipped inside the wheel as `chronocl/kernels/`; in a
source checkout they are read from the top-level `kernels/`. A build failure
raises KernelBuildError naming the file, the options, the device and the
compiler log.
"""

from __future__ import annotations

import threading
from functools import cache
from importlib import resources
from pathlib import Path

from ..errors import KernelBuildError

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


def source(name: str, common: bool = True) -> str:
    """kernels/opencl/NAME, after common.h unless `common` is false."""
    folder = kernel_dir()
    text = (folder / name).read_text()
    return (folder / "common.h").read_text() + "\n" + text if common else text


def build(dc, name: str, defines: dict[str, object], text: str | None = None, common: bool = True):
    """The built program for kernel file `name` with -D `defines` on device context `dc`.

    `text` replaces the file's source; `common` prepends common.h to the file's source.
    """
    import pyopencl as cl

    options = tuple(
        f"-D{key}" if value is True else f"-D{key}={value}"
        for key, value in sorted(defines.items())
        if value is not False and value is not None
    )
    key = (dc.info.index, str(kernel_dir()), name, options, text, common)
    with _lock:
        program = _programs.get(key)
        if program is None:
            src = text if text is not None else source(name, common)
            try:
                program = cl.Program(dc.context, src).build(options=list(options))
            except cl.RuntimeError as exc:
                log = str(exc).strip().replace("\n", " | ")
                raise KernelBuildError(
                    f"building {name} failed on {dc.info.label} with options "
                    f"{' '.join(options) or '(none)'}: {log}"
                ) from None
            _programs[key] = program
    return program


def kernel(dc, name: str, function: str, defines: dict[str, object], common: bool = True):
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
