"""Coarse levels (a pyramid) of a chronocl store, so a session can draw a coarse level first.

Layout: the store's group gains a child group ``levels`` holding ``levels/<n>/<pool>`` for
n = 1..L and pool in POOLS, each (T, z, y, x) of the data's dtype, chunked one step per chunk
along t like ``data``, every chunk written, compressed with a fast lz4 and the data's crc32c. The
``levels`` group's attribute ``chronocl`` (format "chronocl.levels") holds the level-0 shape
the levels were built from and, per level, its shape, its factor (level-0 shape / level shape
per axis) and per pool the per-step min/max/mean.

Rule: level n is ceil(shape_{n-1} / 2) per axis; levels are added while the previous level's
largest axis is > COARSEST. Each level pools 2x2x2 blocks of the previous level of the same
pool (partial blocks at odd edges use the voxels present): "mean" in float64 (integer data
rounded half to even and cast back), "max" and "min" exact. See docs/levels.md.

Writing levels (with a store, or added to one) is `chronocl.data.level_writer`'s; where a
series takes its levels from (this store, pooling on the fly, an image's own) is
`chronocl.data.level_sources`'.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import dask.array as da
import numpy as np
import zarr
from zarr.codecs import BloscCodec

from chronocl.core.errors import ChronoclError, InvalidDataError, InvalidParameterError
from chronocl.data.integrity import CheckedStore, check_byte_order, damaged
from chronocl.data.metadata import SeriesStats, stats_from_steps

POOLS = ("mean", "max", "min")
LEVELS = "levels"
LEVELS_FORMAT = "chronocl.levels"
LEVEL_CODEC = BloscCodec(cname="lz4", clevel=1, shuffle="noshuffle")  # ~3x faster than zstd
# Levels are added while the previous level's largest axis is larger. Part of the store format
# (docs/levels.md): `check_levels` reads stored levels against `level_shapes`.
COARSEST = 64


def level_shapes(volume_shape: Sequence[int]) -> list[tuple[int, int, int]]:
    """The (Z, Y, X) shapes of levels 1..L of a volume of `volume_shape` (level 0)."""
    shape = tuple(int(n) for n in volume_shape)
    shapes = []
    while max(shape) > COARSEST:
        shape = tuple(-(-n // 2) for n in shape)
        shapes.append(shape)
    return shapes  # type: ignore[return-value]


def check_pool(pool: str) -> None:
    if pool not in POOLS:
        raise InvalidParameterError(f"unknown pool {pool!r}; choose one of {', '.join(POOLS)}")


def downsample(
    step: np.ndarray, pool: str, out: np.ndarray | None = None, total: list | None = None
) -> np.ndarray:
    """One (Z, Y, X) step pooled over 2x2x2 blocks: (ceil(Z/2), ceil(Y/2), ceil(X/2)).

    Partial blocks at odd edges pool the voxels present. "mean" is the float64 mean (integer
    dtypes rounded half to even, as np.rint, and cast back); "max" and "min" are exact. `out`,
    if given, receives the result (an array of that shape and the step's dtype). `total`, if
    given, receives the exact sum of the step's values (an int or float).
    """
    check_pool(pool)
    a = np.asarray(step)
    if a.ndim != 3:
        raise InvalidDataError(f"a step to downsample is (Z, Y, X); got shape {a.shape}")
    dtype = a.dtype
    if dtype == np.uint8 and a.flags.c_contiguous and not any(n % 2 for n in a.shape):
        return _pool_uint8(a, pool, out, total)
    if total is not None:
        total.append(a.sum(dtype=_SUMS.get(dtype.kind, np.float64)).item())
    if pool != "mean":
        op = np.maximum if pool == "max" else np.minimum
        for axis in range(3):
            a = _pool_axis(a, axis, op, dtype, out if axis == 2 else None)
        return a
    # Sums of 2x2x2 blocks, a lone edge voxel counted twice along its axis (so every block
    # sums 8 values whose mean is that of the voxels present), in an exact accumulator.
    acc = _ACCUMULATORS.get(dtype.name, np.float64)
    for axis in range(3):
        a = _pool_axis(a, axis, np.add, acc)
    out = np.empty(a.shape, dtype) if out is None else out
    if dtype.kind == "f":
        np.multiply(a, 0.125, out=out, casting="same_kind")
        return out
    q = a >> 3  # the integer mean rounded half to even, exactly as np.rint(a / 8)
    q &= 1
    a += 3
    a += q
    a >>= 3
    np.copyto(out, a, casting="unsafe")
    return out


def _pool_uint8(
    a: np.ndarray, pool: str, out: np.ndarray | None, total: list | None = None
) -> np.ndarray:
    """`downsample` of a C-contiguous uint8 step with even sides: the same values, faster.

    Read as uint16, a row holds its x pairs, one voxel per byte (which byte is which does not
    matter to a sum, a max or a min), so the x pass is a mask, a shift and one operation
    instead of a strided pass over bytes. The mean takes it first, so that every sum is
    formed in uint16 without a cast; max and min take it last, on a quarter of the data.
    """
    byte, shift = np.uint16(0xFF), np.uint16(8)
    if pool == "mean":
        w = a.view(np.uint16)
        s = w[0::2] & byte
        s += w[1::2] & byte
        s += w[0::2] >> shift
        s += w[1::2] >> shift
        s = s[:, 0::2] + s[:, 1::2]
        if total is not None:  # the step's sum from its blocks' sums, a pass over an eighth
            total.append(int(s.sum(dtype=np.uint64)))
        q = s >> np.uint16(3)  # rounded half to even, as in `downsample`
        q &= np.uint16(1)
        s += np.uint16(3)
        s += q
        s >>= np.uint16(3)
    else:
        op = np.maximum if pool == "max" else np.minimum
        zy = op(a[0::2], a[1::2])
        zy = op(zy[:, 0::2], zy[:, 1::2]).view(np.uint16)
        s = op(zy & byte, zy >> shift)
        if total is not None:
            total.append(int(a.sum(dtype=np.uint64)))
    if out is None:
        return s.astype(np.uint8)
    np.copyto(out, s, casting="unsafe")
    return out


_SUMS = {"u": np.uint64, "i": np.int64, "b": np.int64}  # exact sums of a step's values

# Exact sums of 8 values: uint8 in uint16, 16-bit integers in int32, floats in float64.
_ACCUMULATORS = {"uint8": np.uint16, "uint16": np.int32, "int16": np.int32}


def _pool_axis(a: np.ndarray, axis: int, op, acc, out: np.ndarray | None = None) -> np.ndarray:
    """Combine pairs along one axis with `op` into dtype `acc` (into `out` if given); a lone
    last element pairs with itself (an axis of length 1 too)."""
    n = a.shape[axis]

    def at(s: slice) -> tuple[slice, ...]:
        return (slice(None),) * axis + (s,)

    h = n // 2
    if out is None:
        shape = list(a.shape)
        shape[axis] = n - h
        out = np.empty(shape, acc)
    op(a[at(slice(0, 2 * h, 2))], a[at(slice(1, 2 * h, 2))], out=out[at(slice(0, h))], dtype=acc)
    if n % 2:
        last = a[at(slice(n - 1, n))]
        op(last, last, out=out[at(slice(h, n - h))], dtype=acc)
    return out


# -- reading ----------------------------------------------------------------------------------
def describe_levels(volume_shape: Sequence[int], n_levels: int) -> str:
    """'0..2 (256³, 128³, 64³)' for a series with n_levels levels (level 0 included); each
    level's size x×y×z, x first, from `volume_shape` (Z, Y, X)."""
    shapes = [tuple(volume_shape), *level_shapes(volume_shape)][:n_levels]
    text = ", ".join(
        f"{s[0]}³" if len(set(s)) == 1 else "×".join(map(str, s[::-1])) for s in shapes
    )
    return f"{'0' if n_levels == 1 else f'0..{n_levels - 1}'} ({text})"


def read_levels(path: Path, shape: Sequence[int]) -> list[dict] | None:
    """The checked ``levels`` attribute of the store at `path` whose data has `shape`.

    None when the store has no levels; StoreCorruptError when they are damaged or were built
    from another shape. Each level: {"shape", "factor", "stats": {pool: SeriesStats}} with the
    level's own vmin/vmax.
    """
    folder = Path(path) / LEVELS
    if not folder.exists():
        return None
    bad = _bad_levels(path)
    try:
        doc = json.loads((folder / "zarr.json").read_bytes())
    except FileNotFoundError:
        raise bad("its levels group has no metadata (levels/zarr.json is missing)") from None
    except (OSError, ValueError, RecursionError):
        raise bad("its levels metadata levels/zarr.json cannot be read") from None
    return check_levels(doc, path, shape)


def _bad_levels(path: Path | str):
    fix = f"rebuild them with 'chronocl pyramid {path} --force'"

    def bad(what: str) -> Exception:
        return damaged(path, f"{what} ({fix})")

    return bad


def check_levels(doc: object, path: Path | str, shape: Sequence[int]) -> list[dict]:
    """`read_levels` of the levels group's metadata document `doc` (parsed zarr.json) of the
    store at `path` (a local path or a URL, named in errors)."""
    bad = _bad_levels(path)
    attrs = doc.get("attributes", {}).get("chronocl") if isinstance(doc, dict) else None
    if not isinstance(attrs, dict) or attrs.get("format") != LEVELS_FORMAT:
        raise bad("its levels group lacks the chronocl.levels attribute")
    if attrs.get("version") != 1 or attrs.get("chunks") != "complete":
        raise bad(f"its levels attribute has version {attrs.get('version')!r}, not 1")
    shape = [int(n) for n in shape]
    if attrs.get("shape") != shape:
        raise bad(f"its levels were built from shape {attrs.get('shape')}, its data is {shape}")
    want = level_shapes(shape[1:])
    levels = attrs.get("levels")
    if not isinstance(levels, list) or len(levels) != len(want):
        raise bad(f"its levels attribute does not list the {len(want)} levels of {shape[1:]}")
    out = []
    for n, (level, lshape) in enumerate(zip(levels, want, strict=True), 1):
        if not isinstance(level, dict) or level.get("shape") != [shape[0], *lshape]:
            raise bad(f"level {n} is not listed with shape {[shape[0], *lshape]}")
        factor = tuple(a / b for a, b in zip(shape[1:], lshape, strict=True))
        if level.get("factor") != list(factor):
            raise bad(f"level {n} is listed with factor {level.get('factor')}, not {factor}")
        stats = level.get("stats")
        if not isinstance(stats, dict):
            raise bad(f"level {n} lacks its statistics")
        out.append(
            {
                "shape": lshape,
                "factor": factor,
                "stats": {pool: _pool_stats(stats.get(pool), shape[0], bad) for pool in POOLS},
            }
        )
    return out


def _pool_stats(stats: object, t: int, bad) -> SeriesStats:
    lists = [stats.get(k) if isinstance(stats, dict) else None for k in ("step_min", "step_max")]
    lists.append(stats.get("step_mean") if isinstance(stats, dict) else None)
    for values in lists:
        if not (
            isinstance(values, list)
            and len(values) == t
            and all(
                isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                for v in values
            )
        ):
            raise bad(f"its levels statistics are not {t} finite numbers per step")
    return stats_from_steps(*lists)


def open_level_array(
    path: Path | str, n: int, pool: str, shape: Sequence[int], dtype, store=None
) -> zarr.Array:
    """The checked array ``levels/<n>/<pool>`` of the store at `path` (a missing or undecodable
    chunk raises StoreCorruptError on read); `store`, if given, is the checked store to read
    it through (a remote one), else a local one at `path`."""
    name = f"{LEVELS}/{n}/{pool}"
    if store is None:
        store = CheckedStore(path, (name,))
    store.complete = True
    try:
        arr = zarr.open_array(store=store, path=name, mode="r")
    except ChronoclError:  # a remote store's network failure or refusal
        raise
    except Exception:
        raise damaged(path, f"its level array {name} cannot be opened") from None
    check_byte_order(path, arr, name)
    if tuple(arr.shape) != tuple(shape) or arr.dtype != dtype or arr.chunks[0] != 1:
        raise damaged(
            path,
            f"its level array {name} has shape {tuple(arr.shape)} and dtype {arr.dtype}, "
            f"expected {tuple(shape)} and {dtype}",
        )
    return arr


def lazy_level(data: da.Array, n: int, pool: str) -> da.Array:
    """Level n of a (T, Z, Y, X) dask array, pooled lazily step by step (same as stored)."""
    a = data.rechunk((1, -1, -1, -1))
    for lshape in level_shapes(data.shape[1:])[:n]:
        a = a.map_blocks(_pool_block, pool, chunks=(1, *lshape), dtype=a.dtype)
    return a


def _pool_block(block: np.ndarray, pool: str) -> np.ndarray:
    return np.stack([downsample(step, pool) for step in block])


def lazy_stats(a: da.Array, vmin: float, vmax: float) -> SeriesStats:
    """Per-step min/max/mean of a lazy level, with level 0's vmin/vmax."""
    smin, smax, smean = da.compute(
        a.min(axis=(1, 2, 3)), a.max(axis=(1, 2, 3)), a.mean(axis=(1, 2, 3), dtype=np.float64)
    )
    return keep_range(stats_from_steps(smin, smax, smean), vmin, vmax)


def keep_range(stats: SeriesStats, vmin: float, vmax: float) -> SeriesStats:
    """`stats` with the global range [vmin, vmax] of level 0, so one TF maps alike at every
    level."""
    return SeriesStats(vmin, vmax, stats.step_min, stats.step_max, stats.step_mean)
