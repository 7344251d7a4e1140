"""OpenCL device selection and one cached context + queue per device.

`CHRONOCL_DEVICE` picks a device by index ("0:1" = platform 0, device 1) or by a
case-insensitive substring of "platform: device"; `PYOPENCL_CTX` is honoured
the way pyopencl does. Default: the first GPU if there is one, else the first
CPU device, among the devices that can build a kernel: a PoCL whose LLVM is older than
the CPU (PyPI's PoCL 3.0 with LLVM 14 on AMD Zen 4, say) lists its device and then fails
every build with "unknown target CPU 'generic'", so the default passes it over for one
that builds (`build_problem`). Contexts are cached per process and never shared across a fork:
anything multi-process must use the spawn start method (PoCL hangs in a forked
child once a context exists in the parent).
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass, field
from functools import cache

from chronocl.core import env
from chronocl.core.errors import EngineUnavailableError

NO_BUILD = (
    "no OpenCL device here can build kernels ({problems}); install Debian's PoCL, whose LLVM "
    "knows newer CPUs, with 'apt-get install pocl-opencl-icd', or use --engine numpy"
)
NO_PLATFORM = (
    "no OpenCL platform found; install one with 'pip install pyopencl[pocl]' (PoCL on the CPU) "
    "or 'apt-get install pocl-opencl-icd', or use --engine numpy"
)


def _cl():
    try:
        import pyopencl as cl
    except ImportError:
        raise EngineUnavailableError(
            "pyopencl is not installed; 'pip install pyopencl[pocl]', or use --engine numpy"
        ) from None
    return cl


@dataclass(frozen=True)
class DeviceInfo:
    index: str  # "platform:device"
    platform: str
    name: str
    kind: str  # "GPU", "CPU", ...
    version: str
    driver: str
    compute_units: int
    global_mem: int
    max_alloc: int

    @property
    def label(self) -> str:
        return f"{self.platform}: {self.name}"


def _all_devices() -> list[tuple[DeviceInfo, object]]:
    cl = _cl()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        platforms = []
    found = []
    for pi, platform in enumerate(platforms):
        try:
            devices = platform.get_devices()
        except cl.Error:
            continue
        for di, dev in enumerate(devices):
            info = DeviceInfo(
                index=f"{pi}:{di}",
                platform=platform.name.strip(),
                name=dev.name.strip(),
                kind=_kind(cl, dev.type),
                version=dev.version.strip(),
                driver=dev.driver_version.strip(),
                compute_units=dev.max_compute_units,
                global_mem=dev.global_mem_size,
                max_alloc=dev.max_mem_alloc_size,
            )
            found.append((info, dev))
    return found


def _kind(cl, bits: int) -> str:
    for name in ("GPU", "CPU", "ACCELERATOR"):
        if bits & getattr(cl.device_type, name):
            return name
    return "OTHER"


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device of every platform (empty when there is no platform)."""
    return [info for info, _ in _all_devices()]


def pick_device(spec: str | None) -> tuple[DeviceInfo, object]:
    devices = _all_devices()
    if not devices:
        raise EngineUnavailableError(NO_PLATFORM)
    if not spec:
        spec = env.get("CHRONOCL_DEVICE") or env.get("PYOPENCL_CTX")
    spec = spec.strip()
    if spec:
        parts = spec.split(":")
        if parts[0].isdigit() and all(p.isdigit() for p in parts[1:] if p) and len(parts) <= 2:
            wanted = f"{int(parts[0])}:{int(parts[1]) if len(parts) > 1 and parts[1] else 0}"
            for info, dev in devices:
                if info.index == wanted:
                    return info, dev
        else:
            matches = [(i, d) for i, d in devices if spec.lower() in i.label.lower()]
            for info, dev in matches:  # "pocl" may name two PoCLs: the one that builds
                if build_problem(info.index) is None:
                    return info, dev
            if matches:
                return matches[0]
        known = "; ".join(f"{i.index} {i.label}" for i, _ in devices)
        raise EngineUnavailableError(
            f"no OpenCL device matches {spec!r}; available: {known} (see 'chronocl devices')"
        )
    ranked = sorted(devices, key=lambda d: _RANK.get(d[0].kind, len(_RANK)))  # stable
    for info, dev in ranked:
        if build_problem(info.index) is None:
            return info, dev
    raise no_build_error([info for info, _ in devices])


def no_build_error(devices: list[DeviceInfo]) -> EngineUnavailableError:
    """The error for `devices` none of which can build a kernel, naming each one's problem."""
    problems = "; ".join(f"{i.index} {i.label}: {build_problem(i.index)}" for i in devices)
    return EngineUnavailableError(NO_BUILD.format(problems=problems))


_RANK = {"GPU": 0, "CPU": 1}


def usable_devices() -> list[DeviceInfo]:
    """The devices that can build a kernel (see `build_problem`)."""
    return [info for info, _ in _all_devices() if build_problem(info.index) is None]


@cache
def build_problem(index: str) -> str | None:
    """Why device `index` cannot build a kernel (its compiler's first error line), or None.

    Builds kernels/opencl/probe.cl once per process; its context is the one the device
    keeps (`get_context`), so the check costs one tiny build.
    """
    from chronocl.core.errors import KernelBuildError
    from chronocl.engine.program import build

    try:
        build(_context_for(index), "probe.cl", {}, common=False)
    except KernelBuildError as exc:
        text = str(exc)
        first = re.search(r"error: ([^|]+)", text)
        return first.group(1).strip() if first else text
    return None


@dataclass
class DeviceContext:
    """A device with its context and in-order queue (and, made when first asked for, the
    queues and buffers of overlapped brick transfers: `streams`)."""

    info: DeviceInfo
    device: object
    context: object
    queue: object
    lock: threading.Lock
    _streams: object = field(default=None, repr=False)

    @property
    def is_cpu(self) -> bool:
        return "CPU" in self.info.kind and env.get("CHRONOCL_DEVICE_KIND").lower() != "gpu"

    def streams(self):
        """The upload, compute and read-back queues with their reused buffers
        (`chronocl.engine.transfer.Streams`); use them holding `lock`."""
        if self._streams is None:
            from chronocl.engine.transfer import make_streams

            self._streams = make_streams(self.context, self.device)
        return self._streams


@cache
def _context_for(index: str) -> DeviceContext:
    cl = _cl()
    for info, dev in _all_devices():
        if info.index == index:
            ctx = cl.Context([dev])
            return DeviceContext(info, dev, ctx, cl.CommandQueue(ctx), threading.Lock())
    raise EngineUnavailableError(f"OpenCL device {index} disappeared")  # pragma: no cover


def get_context(device: str | None = None) -> DeviceContext:
    """The cached context of the selected device (see module docstring)."""
    info, _ = pick_device(device)
    return _context_for(info.index)
