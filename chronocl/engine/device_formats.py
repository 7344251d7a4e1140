"""The format a brick travels to the device in (`DeviceFormat`, `resolve_format`).

On a GPU the PCIe transfer of a brick, not the kernel, bounds an integration
(docs/engine.md, "Transfers and device formats"), so a brick may travel narrower than it is
stored. ``auto`` sends the stored type (float64 as float32), ``float32`` float32 (integers
widened, a baseline), ``float16`` halves float32 traffic, ``uint8`` / ``uint16`` quantise the
values over the normalising value range. The kernels see quantised data as integers whose
value range is (0, 255) or (0, 65535), so every mode works on them unchanged. Pure numpy:
bricks are encoded on the host (over threads when large) before `chronocl.engine.transfer`
uploads them.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from chronocl.core import host_threads
from chronocl.core.errors import InvalidParameterError, UnknownNameError
from chronocl.core.tuning import TUNING

FORMATS = ("auto", "float32", "uint8", "uint16", "float16")
QUANT_MAX = {"uint8": 255, "uint16": 65535}
HALF_MAX = 65504.0  # the largest finite float16
HALF_EPS = 2.0**-11  # float16 rounding: relative error of a normal value


def stored_dtype(dtype: np.dtype) -> np.dtype:
    """The dtype a brick of `dtype` is integrated in (float64 as float32, like the reference)."""
    return np.dtype(np.float32) if np.dtype(dtype) == np.float64 else np.dtype(dtype)


@dataclass(frozen=True)
class DeviceFormat:
    """How a brick of `source` values travels to the device.

    `dtype` is what the device receives; `quant_max` is 255 or 65535 when the values are
    quantised over `value_range` (the range that normalises them to u), else 0.
    """

    name: str
    source: np.dtype
    dtype: np.dtype
    value_range: tuple[float, float]
    quant_max: int = 0

    @property
    def converts(self) -> bool:
        """Whether bricks are converted on the host before they travel."""
        return self.dtype != self.source

    @property
    def device_range(self) -> tuple[float, float]:
        """The value range the kernels normalise the device values with."""
        if not self.quant_max:
            return self.value_range
        lo, hi = self.value_range
        return (0.0, float(self.quant_max)) if hi > lo else (0.0, 0.0)

    @property
    def max_error(self) -> float:
        """The largest error in u (a fraction of the value range) values inside the range get:
        half a quantisation step, float16 rounding of the largest magnitude, or 0."""
        lo, hi = self.value_range
        if not hi > lo or not self.converts:
            return 0.0
        if self.quant_max:
            return 0.5 / self.quant_max
        if self.dtype == np.float16 and self.source.kind == "f":
            return max(abs(lo), abs(hi)) * HALF_EPS / (hi - lo)
        return 0.0

    def encode(self, src: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """`src` as the device receives it (into `out`, same shape, when given).

        Large bricks are split over threads (numpy releases the GIL): converting on the host
        runs at 2-15 ns per value on one core, slower than PCIe moves the bytes saved, and one
        core's copy into the staging buffer is slower than a PCIe 4/5 link too.
        """
        if out is None:
            out = np.empty(src.shape, self.dtype)
        parts = host_threads.workers() if src.size >= TUNING.format_parallel_min else 1
        if parts > 1 and src.flags.c_contiguous and out.flags.c_contiguous:
            flat_src, flat_out = src.reshape(-1), out.reshape(-1)
            bounds = np.linspace(0, src.size, parts + 1).astype(int)
            pieces = [slice(a, b) for a, b in itertools.pairwise(bounds)]
            list(host_threads.pool().map(lambda p: self._encode(flat_src[p], flat_out[p]), pieces))
            return out
        return self._encode(src, out)

    def _encode(self, src: np.ndarray, out: np.ndarray) -> np.ndarray:
        if not self.converts:
            np.copyto(out, src)
        elif self.quant_max:
            out[...] = quantize(src, self.value_range, self.quant_max)
        elif self.dtype == np.float16:
            # Saturating: a value past float16's range becomes its largest finite value, which
            # normalises like the clipped value would (the range itself fits float16).
            np.clip(src, -HALF_MAX, HALF_MAX, out=out, casting="unsafe")
        else:
            out[...] = src
        return out


def quantize(values: np.ndarray, value_range: tuple[float, float], q_max: int) -> np.ndarray:
    """Values clipped to `value_range` and mapped linearly onto 0..q_max, rounded to nearest, in
    float32 arithmetic: q = rint((clip(v) - vmin) * (q_max / (vmax - vmin))). A constant range
    gives 0 everywhere. The result is float32 holding whole numbers."""
    lo, hi = value_range
    v = np.asarray(values, dtype=np.float32)
    if not hi > lo:
        return np.zeros(v.shape, np.float32)
    lo32, hi32 = np.float32(lo), np.float32(hi)
    q = (np.clip(v, lo32, hi32) - lo32) * np.float32(q_max / (float(hi) - float(lo)))
    np.rint(q, out=q)
    return np.clip(q, np.float32(0), np.float32(q_max), out=q)


def check_format_name(name: str) -> str:
    """A device format chronocl has (checked before any work)."""
    if name not in FORMATS:
        raise UnknownNameError(
            f"unknown device format {name!r}; choose one of {', '.join(FORMATS)}"
        )
    return name


def resolve_format(
    name: str,
    dtype: np.dtype,
    value_range: tuple[float, float],
    mode: str | None = None,
    data_range: tuple[float, float] | None = None,
) -> DeviceFormat:
    """The device format `name` for data stored as `dtype`, normalised over `value_range`, for
    integration `mode` on data whose values span `data_range` (max and min refuse a
    quantising that clips them: `_no_clipped_extremes`).

    Refuses (one line, InvalidParameterError) a format that would not make the brick smaller
    than it is stored and is lossy or wider (uint16 or float16 for uint8 data, float16 or uint16
    for 16-bit integers), and float16 where it cannot hold the range or resolves it more
    coarsely than uint8 would.
    """
    check_format_name(name)
    src = stored_dtype(dtype)
    lo, hi = float(value_range[0]), float(value_range[1])
    if name == "auto":
        return DeviceFormat(name, src, src, (lo, hi))
    if name == "float32":  # integer data widened: a baseline to compare the compact formats with
        return DeviceFormat(name, src, np.dtype(np.float32), (lo, hi))
    target = np.dtype(name)
    if target == src:
        return DeviceFormat(name, src, src, (lo, hi))
    if target.itemsize >= src.itemsize:
        raise InvalidParameterError(
            f"--device-format {name} would send {src.name} data in {target.itemsize} bytes per "
            f"value, not fewer than the {src.itemsize} they are stored in; use auto"
        )
    if name == "float16":
        big = max(abs(lo), abs(hi))
        if big > HALF_MAX:
            raise InvalidParameterError(
                f"--device-format float16 cannot hold the value range {lo:g}..{hi:g} (float16 "
                f"ends at {HALF_MAX:g}); use uint16 (quantised over the range) or auto"
            )
        fmt = DeviceFormat(name, src, target, (lo, hi))
        if fmt.max_error > 0.5 / QUANT_MAX["uint8"]:
            raise InvalidParameterError(
                f"--device-format float16 resolves values near {big:g} only to "
                f"{big * HALF_EPS:.3g}, {100 * fmt.max_error:.2g}% of the value range "
                f"{lo:g}..{hi:g} (coarser than uint8); use uint16 or auto"
            )
        return fmt
    _no_clipped_extremes(name, mode, (lo, hi), data_range)
    return DeviceFormat(name, src, target, (lo, hi), QUANT_MAX[name])


def _no_clipped_extremes(name: str, mode, value_range, data_range) -> None:
    """max and min compare the raw values (their winner is the raw extreme, DESIGN.md);
    quantising clips them to the value range, where the values beyond it would tie: refused
    where the data reach beyond it (the data's range unknown, as in the engine: allowed)."""
    if mode not in ("max", "min") or data_range is None:
        return
    (lo, hi), (vmin, vmax) = value_range, data_range
    if vmin < lo or vmax > hi:
        raise InvalidParameterError(
            f"--device-format {name} clips the values to the value range {lo:g}..{hi:g}, where "
            f"{mode}'s raw extremes would tie (the data span {vmin:g}..{vmax:g}); give "
            "--value-range series, or use float16 or auto"
        )


def with_device_format(
    engine,
    name: str,
    dtype: np.dtype,
    value_range: tuple[float, float],
    mode: str | None = None,
    data_range: tuple[float, float] | None = None,
):
    """`engine` set to send bricks in device format `name` (checked now, before any work).

    ``auto`` keeps the engine as it is (with any format it was made with); another format needs
    an engine that copies bricks to a device (the OpenCL one).
    """
    if check_format_name(name) == "auto":
        return engine
    copies = hasattr(engine, "with_options")  # the OpenCL engine; any other is refused by name
    label = "opencl" if copies else getattr(engine, "name", type(engine).__name__)
    check_device_format(name, label, dtype, value_range, mode, data_range)
    return engine.with_options(device_format=name)


def check_device_format(
    name: str,
    engine: str,
    dtype: np.dtype,
    value_range: tuple[float, float],
    mode: str | None = None,
    data_range: tuple[float, float] | None = None,
) -> DeviceFormat:
    """Check device format `name` for an engine by name and the data (before any work)."""
    check_format_name(name)
    if name != "auto" and engine != "opencl":
        raise InvalidParameterError(
            f"--device-format {name} applies to the opencl engine; the {engine} engine reads "
            "the data as stored (use --device-format auto)"
        )
    return resolve_format(name, dtype, value_range, mode, data_range)
