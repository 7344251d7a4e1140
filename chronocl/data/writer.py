"""Writing time steps into a new chronocl store, atomically, gathering statistics on the way.

Store layout (zarr v3): a group whose array ``data`` is (T, Z, Y, X), chunked (1, zc, Y, X) so
one step is one small set of chunks, and whose attribute ``chronocl`` holds the global value
range, per-step min/max/mean, voxel spacing, time labels and a source description. Every chunk
is written, empty ones included, so a missing chunk always means damage. With `levels` (the
default) the coarse levels (`chronocl.data.pyramid`, docs/levels.md) are written in the same
pass, each step pooled as it is written.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np
import zarr
from zarr.codecs import BloscCodec, Crc32cCodec, ZstdCodec

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import InvalidDataError, InvalidParameterError
from chronocl.core.progress import track
from chronocl.core.times_meta import Cadence
from chronocl.core.tuning import TUNING
from chronocl.data.level_writer import LevelWriter
from chronocl.data.metadata import (
    FORMAT,
    check_dtype,
    check_shape,
    parse_spacing,
    parse_times,
    stats_from_steps,
)
from chronocl.data.pyramid import LEVELS, level_shapes
from chronocl.data.remote_store import is_url

# Optional attributes a store may record beside its statistics (`write_store(attrs=...)`):
# `variable` (its name) and `variables` (all of a multi-variable store, whose others sit in
# VARIABLES/<name>/ as stores of their own), `quantity` ("magnitude") and its `components`,
# `resampled` (notes on coordinates resampled to uniform spacing).
EXTRA_KEYS = ("variable", "variables", "quantity", "components", "resampled", "time_unit")
VARIABLES = "variables"
COMPRESSORS = ("zstd", "blosc-lz4", "none")


def compressors(name: str, checksum: bool = True) -> object:
    """zarr v3 compressors for a name in COMPRESSORS (zstd level 0 is zarr's default).

    With `checksum` a crc32c of every encoded chunk follows the compressor, so a chunk whose
    bytes changed on disk fails to read (StoreCorruptError) instead of decoding to other values.
    """
    if name not in COMPRESSORS:
        raise InvalidParameterError(
            f"unknown compressor {name!r}; choose one of {', '.join(COMPRESSORS)}"
        )
    chain = {
        "zstd": [ZstdCodec(level=0)],
        "blosc-lz4": [BloscCodec(cname="lz4", clevel=5, shuffle="shuffle")],
        "none": [],
    }[name]
    if checksum:
        chain.append(Crc32cCodec())
    return tuple(chain) or None


def write_store(
    path: str | os.PathLike,
    steps: Iterable[np.ndarray],
    *,
    n_steps: int,
    volume_shape: Sequence[int],
    dtype: object,
    spacing: Sequence[float] = (1.0, 1.0, 1.0),
    times: Sequence | None = None,
    source: str = "",
    overwrite: bool = False,
    progress: bool = False,
    nan_fill: float | None = None,
    labels: Sequence[str] | None = None,
    chunk_bytes: int | None = None,  # None: TUNING.chunk_bytes
    compressor: str = "zstd",
    checksum: bool = True,
    levels: bool = True,
    attrs: dict | None = None,
    storage_options: dict | None = None,
) -> None:
    """Write steps (each (Z, Y, X)) to a new store at `path` atomically; `spacing` is (dx, dy,
    dz), x first. `path` may be an s3:// URL: the store is published whole, root metadata
    last (`chronocl.data.remote_write`, given `storage_options`).

    Non-finite values are rejected unless `nan_fill` is given, which replaces them.
    `labels` name each step's origin (e.g. its file) in error messages. Chunks are
    (1, zc, Y, X) of at most `chunk_bytes` (None: `TUNING.chunk_bytes`; small chunks suit small
    streaming budgets);
    `compressor` is one of COMPRESSORS; `checksum` adds a crc32c per chunk. `levels` adds
    the coarse levels (group ``levels``) in the same pass when the volume has any. `attrs`
    adds the EXTRA_KEYS it has to the store's metadata.
    """
    if is_url(str(path)):
        from chronocl.data.remote_write import remote_output

        with remote_output(str(path), overwrite, storage_options) as local:
            return write_store(
                local, steps, n_steps=n_steps, volume_shape=volume_shape, dtype=dtype,
                spacing=spacing, times=times, source=source, progress=progress,
                nan_fill=nan_fill, labels=labels, chunk_bytes=chunk_bytes,
                compressor=compressor, checksum=checksum, levels=levels, attrs=attrs,
            )  # fmt: skip
    chunk_bytes = TUNING.chunk_bytes if chunk_bytes is None else chunk_bytes
    dt = np.dtype(dtype)
    check_dtype(dt)
    extra = {k: v for k, v in (attrs or {}).items() if v}
    if set(extra) - set(EXTRA_KEYS):
        raise InvalidParameterError(
            f"unknown store attributes {sorted(set(extra) - set(EXTRA_KEYS))}; "
            f"choose from {', '.join(EXTRA_KEYS)}"
        )
    if nan_fill is not None and not (
        isinstance(nan_fill, int | float | np.number) and math.isfinite(nan_fill)
    ):
        raise InvalidParameterError(
            f"--nan-fill {nan_fill} must be a finite number (it replaces NaN and infinite values)"
        )
    given = times is not None and (isinstance(times, Cadence) or len(times) > 0)
    if "time_unit" in extra and not given:
        raise InvalidParameterError(
            f"a time unit ({extra['time_unit']}) needs the steps' times; give --times (times=)"
        )
    shape = (int(n_steps), *(int(n) for n in volume_shape))
    check_shape(shape, source or str(path))
    spacing = parse_spacing(spacing)
    times = parse_times(times, n_steps)
    z, y, x = shape[1:]
    zc = max(1, min(z, int(chunk_bytes) // max(1, y * x * dt.itemsize)))
    codecs = compressors(compressor, checksum)
    smin, smax, smean = [], [], []
    with atomic_directory(path, overwrite) as tmp:
        group = zarr.open_group(store=str(tmp), mode="w", zarr_format=3)
        arr = group.create_array(
            "data",
            shape=shape,
            chunks=(1, zc, y, x),
            dtype=dt,
            compressors=codecs,
            config={"write_empty_chunks": True},  # a missing chunk then always means damage
        )
        pyramid = None
        if levels and level_shapes(shape[1:]):
            pyramid = LevelWriter(
                group.create_group(LEVELS), shape, dt, codecs, chunk_bytes=chunk_bytes
            )
        count = 0
        # A step's levels are pooled on one thread while the step itself is written, and their
        # chunks are written on another while the next step is: the step's buffer is free once
        # it is written and pooled (the caller may reuse it), the levels' chunks are not.
        pools = ThreadPoolExecutor(1, thread_name_prefix="chronocl-levels") if pyramid else None
        writes = (
            ThreadPoolExecutor(1, thread_name_prefix="chronocl-level-writes") if pyramid else None
        )
        # the previous step's level write, at most one in flight; first the arrays' creation
        written = writes.submit(pyramid.create) if pyramid else None
        try:
            for t, step in enumerate(track(steps, n_steps, "writing steps", progress)):
                step = _checked_step(step, t, shape, dt, nan_fill, labels, n_steps)
                pooled = pools.submit(pyramid.pool, t, step) if pools else None
                try:
                    arr[t] = step
                    if pooled is None:  # else the pooling gives them
                        smin.append(float(step.min()))
                        smax.append(float(step.max()))
                        smean.append(float(step.mean(dtype=np.float64)))
                finally:  # the caller may reuse the step's buffer once it has the next
                    if pooled is not None:
                        wait([pooled])
                if pooled is not None:
                    done = pooled.result()
                    smin.append(done.minimum)
                    smax.append(done.maximum)
                    smean.append(done.mean)
                    if written is not None:
                        written.result()
                    written = writes.submit(pyramid.write, t, done)
                count += 1
            if written is not None:
                written.result()
        finally:
            for executor in (pools, writes):
                if executor is not None:
                    executor.shutdown()
        if count != n_steps:
            raise InvalidDataError(f"got {count} time steps, expected {n_steps}")
        if pyramid is not None:
            pyramid.finish()
        stats = stats_from_steps(smin, smax, smean)
        group.attrs["chronocl"] = {
            "format": FORMAT,
            "version": 1,
            "chunks": "complete",
            "vmin": stats.vmin,
            "vmax": stats.vmax,
            "step_min": list(stats.step_min),
            "step_max": list(stats.step_max),
            "step_mean": list(stats.step_mean),
            "spacing": dict(zip("xyz", spacing, strict=True)),
            "times": list(times),
            "source": source,
            **extra,
        }


def _checked_step(step, t, shape, dt, nan_fill, labels, n_steps) -> np.ndarray:
    """Step `t` as a C-contiguous array of the store's dtype, its non-finite values replaced
    by `nan_fill` (else rejected)."""
    where = labels[t] if labels else f"time step {t}"
    step = np.asarray(step)
    if t >= n_steps:
        raise InvalidDataError(f"got more than the {n_steps} steps announced")
    if step.shape != shape[1:]:
        raise InvalidDataError(f"{where} has shape {step.shape}, expected {shape[1:]} (Z, Y, X)")
    if dt.kind == "f":
        bad = ~np.isfinite(step)
        n_bad = int(bad.sum())
        if n_bad:
            if nan_fill is None:
                raise InvalidDataError(
                    f"{where} has {n_bad} NaN/infinite values; pass --nan-fill VALUE "
                    "(nan_fill=...) to replace them"
                )
            step = np.where(bad, dt.type(nan_fill), step)
    return np.ascontiguousarray(step.astype(dt, copy=False))
