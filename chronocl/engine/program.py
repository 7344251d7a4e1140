"""Kernel sources from `kernels/opencl/`, built once per (context, options) and cached.

Kernels live in files, shipped inside the wheel as `chronocl/kernels/`; in a
source checkout they are read from the top-level `kernels/`. A build failure
raises KernelBuildError naming the file, the options, the device and the
compiler log.

Builds are quiet: the compiler's log and pyopencl's CompilerWarning are captured, never
printed, unless CHRONOCL_VERBOSE=1 (the CLI's --verbose), which prints a non-empty log to
stderr after the file name, options and device. The kernels themselves build without
warnings on PoCL (tests/test_kernel_build.py), so clang has nothing to print either.

Built programs are kept as the driver's binaries in `cache_dir()` (CHRONOCL_PROGRAM_CACHE,
"off" for none; default `$XDG_CACHE_HOME/chronocl/programs`), one file per source, options,
device, driver and PoCL settings, with a checksum: the next process loads the binary instead
of building again. PoCL keeps a cache of its own, but finds its entries only after running
the preprocessor over the source (about 0.1 s a program here, against 0.007 s to load a
binary), and keys them on pyopencl's options too, which name pyopencl's own folder: a
second virtual environment (CI's second interpreter) built every program again. A binary
whose checksum fails, or that the driver refuses, is built again from source and replaced.
A loaded binary has no compiler log to show: --verbose prints the logs of real builds.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import sys
import threading
import uuid
import warnings
from functools import cache
from importlib import resources
from pathlib import Path

from chronocl.core.errors import KernelBuildError

log = logging.getLogger("chronocl")

CACHE_VAR = "CHRONOCL_PROGRAM_CACHE"  # a folder for built programs' binaries; "off": none
# Environment variables (names, or prefixes ending in _) that change what a driver builds:
# PoCL's settings (its CPU target, ...), the options pyopencl adds to every build, other
# drivers' build options. Not PYOPENCL_HOME: pyopencl sets it to its own folder, another in
# every virtual environment, and keying on it would miss in each (CI's second interpreter).
BUILD_VARIABLES = ("POCL_", "PYOPENCL_BUILD_OPTIONS", "AMD_OCL_BUILD_OPTIONS", "RUSTICL_", "IGC_")
_MAGIC = b"chronocl-program 1\n"

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
    header instead, e.g. the recolouring's recolour.h)."""
    folder = kernel_dir()
    text = (folder / name).read_text()
    header = "common.h" if common is True else common
    return (folder / header).read_text() + "\n" + text if header else text


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


def cache_dir() -> Path | None:
    """Where built programs' binaries are kept (see the module docstring); None: nowhere."""
    value = os.environ.get(CACHE_VAR, "").strip()
    if value.lower() in ("off", "0", "no", "false", "none"):
        return None
    if value:
        return Path(value)
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):  # unset, or relative: ignored, as the XDG spec says
        base = os.path.join(os.path.expanduser("~"), ".cache")
    if not os.path.isabs(base):  # no home to keep it in
        return None
    return Path(base) / "chronocl" / "programs"


def binary_path(dc, src: str, options: tuple[str, ...]) -> Path | None:
    """The cache file of `src` built with `options` on `dc`'s device (None: no cache). The
    key holds everything a binary depends on: the source, the options, the device, its
    driver and platform, and the environment's `BUILD_VARIABLES`."""
    folder = cache_dir()
    if folder is None:
        return None
    d = dc.device
    parts = [src, " ".join(options), d.name, d.vendor, d.version, d.driver_version]
    parts += [d.platform.name, d.platform.version]
    parts += sorted(
        f"{k}={v}"
        for k, v in os.environ.items()
        if k.startswith(BUILD_VARIABLES) and k != "POCL_CACHE_DIR"
    )
    return folder / (hashlib.sha256("\0".join(parts).encode()).hexdigest() + ".bin")


def _load(dc, path: Path, options: tuple[str, ...]):
    """The program built from the binary at `path`, or None where there is none, its
    checksum fails or the driver refuses it (the caller builds from source and replaces it)."""
    import pyopencl as cl

    try:
        data = path.read_bytes()
    except OSError:
        return None
    head, _, binary = data.partition(b"\n\n")
    if head != _MAGIC + hashlib.sha256(binary).hexdigest().encode():
        log.debug("chronocl: the cached program %s is damaged; building it again", path)
        return None
    # a driver may keep the build's log with the binary: quiet as a build (`_compile`)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cl.CompilerWarning)
        try:
            return cl.Program(dc.context, [dc.device], [binary]).build(options=list(options))
        except cl.Error as exc:
            log.debug("chronocl: the driver refused the cached program %s (%s)", path, exc)
            return None


def _store(path: Path, program) -> None:
    """Keep `program`'s binary at `path`: written aside, then renamed over it, so a reader
    sees a whole file or none; a cache that cannot be written is left as it is."""
    import pyopencl as cl

    try:
        binaries = program.get_info(cl.program_info.BINARIES)
    except cl.Error:  # pragma: no cover - a driver that gives no binaries
        return
    if len(binaries) != 1 or not binaries[0]:
        return
    binary = bytes(binaries[0])
    aside = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        aside.write_bytes(_MAGIC + hashlib.sha256(binary).hexdigest().encode() + b"\n\n" + binary)
        os.replace(aside, path)
    except OSError as exc:
        log.debug("chronocl: cannot keep the built program at %s (%s)", path, exc)
        with contextlib.suppress(OSError):
            aside.unlink(missing_ok=True)


def verbose() -> bool:
    """Whether kernel build logs are shown (CHRONOCL_VERBOSE=1, set by the CLI's --verbose)."""
    return os.environ.get("CHRONOCL_VERBOSE", "").strip().lower() in ("1", "true", "yes", "on")


def _compile(dc, name: str, src: str, options: tuple[str, ...]):
    """`src` built on `dc`: loaded from the binary cache, or built with the compiler's output
    captured (see the module docstring) and its binary kept."""
    import pyopencl as cl

    path = binary_path(dc, src, options)
    program = _load(dc, path, options) if path is not None else None
    if program is not None:
        return program

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
    if path is not None:
        _store(path, program)
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
