"""Writing the coarse levels of a chronocl store (the rule and reading: `chronocl.data.pyramid`).

`LevelWriter` pools each step into every level and pool while `write_store` writes the step
itself, and writes the levels' chunks while the next step is written. `add_levels` adds levels
to an existing store without touching ``data`` or the root's attributes: it builds them at a
hidden sibling ``.levels.partial-<pid>-<hex>`` inside the store and renames that to ``levels``
when complete (chronocl.core.atomic).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import google_crc32c
import numpy as np
import zarr
from numcodecs import Blosc
from numcodecs.blosc import list_compressors
from zarr.codecs import Crc32cCodec
from zarr.storage import LocalStore

from chronocl.core.atomic import partial_path, remove_path, remove_stale, replace
from chronocl.core.errors import InvalidDataError, StoreFormatError
from chronocl.core.progress import track
from chronocl.core.tuning import TUNING
from chronocl.data.integrity import CheckedStore, checked_read
from chronocl.data.metadata import FORMAT, checked_attrs
from chronocl.data.pyramid import (
    COARSEST,
    LEVEL_CODEC,
    LEVELS,
    LEVELS_FORMAT,
    POOLS,
    describe_levels,
    downsample,
    level_shapes,
    read_levels,
)
from chronocl.data.stores import require_store


def level_compressors(data_compressors: object) -> tuple:
    """The codecs of the levels: a fast lz4, then a crc32c when the data's chain has one."""
    checked = any(isinstance(c, Crc32cCodec) for c in data_compressors or ())
    return (LEVEL_CODEC, Crc32cCodec()) if checked else (LEVEL_CODEC,)


@dataclass(frozen=True)
class Pooled:
    """A step pooled into every level and pool (`levels`, by (n, pool)), and the step's own
    minimum, maximum and mean, which the pooling gives almost for free."""

    levels: dict
    minimum: float
    maximum: float
    mean: float


class LevelWriter:
    """Writes levels 1..L of a series into a zarr group while the caller streams the steps.

    `add(t, step)` pools one level-0 step into every level and pool and writes them; `finish()`
    checks that every step came and writes the group's ``chronocl`` attribute. The level
    arrays are created by `create()`, or by the first write: creating six arrays through zarr
    costs tens of milliseconds, which `write_store` spends on its writer thread.
    """

    def __init__(
        self,
        group: zarr.Group,
        shape: Sequence[int],
        dtype: object,
        compressors: object,
        chunk_bytes: int,
    ) -> None:
        self.group, self.shape, self.dtype = group, tuple(int(n) for n in shape), np.dtype(dtype)
        self.shapes = level_shapes(self.shape[1:])
        self.compressors, self.chunk_bytes = level_compressors(compressors), int(chunk_bytes)
        self._arrays: dict | None = None
        self.stats = {
            (n, pool): ([], [], []) for n in range(1, len(self.shapes) + 1) for pool in POOLS
        }
        self.done = 0

    def create(self) -> None:
        """Create the level arrays in the group (once)."""
        if self._arrays is not None:
            return
        arrays = {}
        for n, (z, y, x) in enumerate(self.shapes, 1):
            sub = self.group.require_group(str(n))
            zc = max(1, min(z, self.chunk_bytes // max(1, y * x * self.dtype.itemsize)))
            for pool in POOLS:
                arrays[n, pool] = sub.create_array(
                    pool,
                    shape=(self.shape[0], z, y, x),
                    chunks=(1, zc, y, x),
                    dtype=self.dtype,
                    compressors=self.compressors,
                    config={"write_empty_chunks": True},  # a missing chunk means damage
                    # Chunk files side by side (c.T.Z.0.0), not in a folder per step and
                    # chunk: six new folders a step cost more than pooling it on ext4.
                    chunk_key_encoding={"name": "default", "separator": "."},
                )
        files = {key: chunk_files(a) for key, a in arrays.items()}
        self._files = files if all(f is not None for f in files.values()) else None
        self._arrays = arrays

    @property
    def arrays(self) -> dict:
        self.create()
        return self._arrays

    @property
    def direct(self) -> bool:
        """Whether the chunks are written as files by `_write_step_chunks` (else by zarr)."""
        self.create()
        return self._files is not None

    def add(self, t: int, step: np.ndarray) -> None:
        """Pool step `t` (Z, Y, X) into every level and pool and write them."""
        self.write(t, self.pool(t, step))

    def pool(self, t: int, step: np.ndarray) -> Pooled:
        """Step `t` (Z, Y, X) pooled into every level and pool, its statistics recorded.

        Steps come in order. The step is pooled in z-slabs of about `TUNING.pyramid_slab_bytes` (a
        multiple of 2^L planes, so every level's slab starts on an even plane), which stay in the
        CPU's cache through all levels. Only this reads `step`; `write` needs just the result. The
        step's own minimum and maximum are those of level 1's min and max pools, and its sum comes
        with level 1's mean (`downsample`'s `total`), so `write_store` need not read the step again
        for its statistics.
        """
        if t != self.done:
            raise InvalidDataError(f"levels got time step {t}, expected {self.done}")
        depth = len(self.shapes)
        plane = max(1, step[0].nbytes)
        planes = max(1, TUNING.pyramid_slab_bytes // plane >> depth) << depth
        out = {
            (n, pool): np.empty(self.shapes[n - 1], self.dtype)
            for n in range(1, depth + 1)
            for pool in POOLS
        }
        parts = {key: ([], [], []) for key in out}
        # Exact integer sums of integer levels (no float conversion); float levels in float64.
        acc = (
            np.uint64
            if self.dtype.kind == "u"
            else np.int64
            if self.dtype.kind == "i"
            else np.float64
        )
        step_sums: list = []  # the step's own sum, slab by slab
        for z0 in range(0, step.shape[0], planes):
            for pool in POOLS:
                a = step[z0 : z0 + planes]
                for n in range(1, depth + 1):
                    z = z0 >> n
                    sums = step_sums if n == 1 and pool == "mean" else None
                    a = downsample(a, pool, out[n, pool][z : z + (a.shape[0] + 1) // 2], sums)
                    lo, hi, total = parts[n, pool]  # statistics while the slab is in cache
                    lo.append(a.min())
                    hi.append(a.max())
                    total.append(a.sum(dtype=acc))
        for key, a in out.items():
            lo, hi, total = parts[key]
            smin, smax, smean = self.stats[key]
            smin.append(float(min(lo)))
            smax.append(float(max(hi)))
            smean.append(float(math.fsum(float(v) for v in total) / a.size))
        self.done += 1
        return Pooled(
            out,
            minimum=self.stats[1, "min"][0][-1],
            maximum=self.stats[1, "max"][1][-1],
            mean=math.fsum(float(v) for v in step_sums) / step.size,
        )

    def write(self, t: int, pooled: Pooled) -> None:
        """Write step `t`'s levels (what `pool` returned) into their arrays."""
        if self.direct:
            for key, a in pooled.levels.items():
                _write_step_chunks(self.arrays[key], t, a, self._files[key])
        else:
            _write_together([(self.arrays[key], t, a) for key, a in pooled.levels.items()])

    def finish(self) -> None:
        self.create()
        if self.done != self.shape[0]:
            raise InvalidDataError(f"levels got {self.done} time steps, expected {self.shape[0]}")
        levels = []
        for n, lshape in enumerate(self.shapes, 1):
            stats = {}
            for pool in POOLS:
                smin, smax, smean = self.stats[n, pool]
                stats[pool] = {"step_min": smin, "step_max": smax, "step_mean": smean}
            factor = [a / b for a, b in zip(self.shape[1:], lshape, strict=True)]
            levels.append({"shape": [self.shape[0], *lshape], "factor": factor, "stats": stats})
        self.group.attrs["chronocl"] = {
            "format": LEVELS_FORMAT,
            "version": 1,
            "chunks": "complete",
            "shape": list(self.shape),
            "pools": list(POOLS),
            "levels": levels,
        }


# numcodecs' Blosc shuffle codes for zarr v3's blosc configuration
_SHUFFLES = {"noshuffle": Blosc.NOSHUFFLE, "shuffle": Blosc.SHUFFLE, "bitshuffle": Blosc.BITSHUFFLE}


@dataclass(frozen=True)
class ChunkFiles:
    """Where and how `_write_step_chunks` writes an array's chunks as files, read from the
    array's zarr v3 metadata as the specification spells it (`Array.metadata.to_dict()`, the
    ``zarr.json`` document): its folder, chunk key separator, blosc settings, crc32c and fill."""

    root: Path
    separator: str
    blosc: Blosc | None
    crc: bool
    fill: object


def chunk_files(arr: zarr.Array) -> ChunkFiles | None:
    """How to write `arr`'s chunks as files, or None when zarr must write them.

    Files are written for a zarr v3 array in a local directory, keys of the default encoding,
    whose codecs are bytes (little-endian), then optionally blosc, then optionally crc32c: the
    chains `level_compressors` makes. Anything else (another store, codec or key encoding, one
    a newer zarr spells otherwise) is left to zarr.
    """
    if not isinstance(arr.store, LocalStore):
        return None
    meta = arr.metadata.to_dict()
    keys = meta.get("chunk_key_encoding") or {}
    if (
        meta.get("zarr_format") != 3
        or meta.get("storage_transformers")
        or keys.get("name") != "default"
    ):
        return None
    codecs = [(c.get("name"), c.get("configuration") or {}) for c in meta.get("codecs") or ()]
    if not codecs or codecs[0][0] != "bytes" or codecs[0][1].get("endian", "little") != "little":
        return None
    rest, blosc = codecs[1:], None
    if rest and rest[0][0] == "blosc":
        conf = rest.pop(0)[1]
        shuffle = _SHUFFLES.get(conf.get("shuffle"))
        if shuffle is None or conf.get("cname") not in list_compressors():
            return None
        # typesize: numcodecs takes the itemsize of the typed array it encodes, as zarr does
        blosc = Blosc(
            cname=conf["cname"],
            clevel=int(conf.get("clevel", 5)),
            shuffle=shuffle,
            blocksize=int(conf.get("blocksize", 0)),
        )
    crc = bool(rest) and rest[0][0] == "crc32c"
    if crc:
        rest.pop(0)
    if rest:
        return None
    root = Path(str(arr.store.root)) / arr.path
    return ChunkFiles(
        root, keys.get("configuration", {}).get("separator", "/"), blosc, crc, arr.fill_value
    )


def _write_step_chunks(arr: zarr.Array, t: int, a: np.ndarray, files: ChunkFiles) -> None:
    """Write step `t` of `arr` (chunks (1, zc, Y, X)) as encoded chunk files, as zarr would.

    The levels' chunks are small and many; zarr's asynchronous pipeline costs several times
    the encoding itself per chunk, and it shares its one event loop with the data being written
    beside the levels. The encoding is zarr v3's, done by the same libraries (numcodecs' blosc,
    google-crc32c), and tests compare the files with zarr's own byte for byte. Edge chunks are
    padded with the fill value, as zarr v3 stores them.
    """
    zc = int(arr.chunks[1])
    little = a.dtype.newbyteorder("<")
    for i, z0 in enumerate(range(0, a.shape[0], zc)):
        part = a[z0 : z0 + zc]
        if part.shape[0] < zc:  # zarr v3 keeps edge chunks at full size
            full = np.full((zc, *a.shape[1:]), files.fill, little)
            full[: part.shape[0]] = part
            part = full
        raw = np.ascontiguousarray(part, little)
        data = files.blosc.encode(raw) if files.blosc is not None else raw.tobytes()
        # zarr v3's default chunk key: "c", then the chunk's coordinates, by the separator
        file = files.root / files.separator.join(("c", str(t), str(i), "0", "0"))
        if file.parent != files.root:  # "/"-separated keys: a folder per step and chunk
            file.parent.mkdir(parents=True, exist_ok=True)
        with open(file, "wb") as f:
            f.write(data)
            if files.crc:
                f.write(google_crc32c.value(data).to_bytes(4, "little"))


def _write_together(writes: list[tuple[zarr.Array, int, np.ndarray]]) -> None:
    """Write step t of several arrays at once: one thread per array, so zarr encodes and
    stores their chunks concurrently (one call after another costs a round trip through zarr's
    event loop each)."""

    def write(item: tuple[zarr.Array, int, np.ndarray]) -> None:
        arr, t, a = item
        arr[t] = a

    if len(writes) == 1:  # no thread for one array
        write(writes[0])
        return
    with ThreadPoolExecutor(len(writes)) as pool:
        list(pool.map(write, writes))


NOTHING_TO_ADD = f"nothing to add: levels are made while the largest axis is > {COARSEST}"
PRESENT = "levels already present (pass --force to rebuild them)"


def levels_summary(store: str, shape: tuple[int, ...], n_levels: int, status: str) -> dict:
    """What `chronocl pyramid` reports of the store `store` of (T, Z, Y, X) `shape`."""
    return {"store": store, "levels": describe_levels(shape[1:], n_levels), "status": status}


def add_levels(path: str | os.PathLike, progress: bool = False, force: bool = False) -> dict:
    """Add coarse levels to the chronocl store at `path`; returns a summary.

    ``data`` and the root's attributes are only read. The levels are built at a hidden
    sibling inside the store and renamed to ``levels`` when complete, so a killed build leaves
    no ``levels`` (its partial is removed by the next build). Existing levels are kept unless
    `force`, which builds new ones and swaps them in.
    """
    p = Path(path)
    arr = _open_data(p)
    shape = tuple(int(n) for n in arr.shape)
    target = p / LEVELS
    remove_stale(target)  # partials of builds that were killed
    if not level_shapes(shape[1:]):
        return levels_summary(str(p), shape, 1, NOTHING_TO_ADD)
    if target.exists() and not force:
        read_levels(p, shape)  # damaged levels are reported, not kept silently
        return levels_summary(str(p), shape, 1 + len(level_shapes(shape[1:])), PRESENT)
    zc = int(arr.chunks[1])
    chunk_bytes = zc * shape[2] * shape[3] * arr.dtype.itemsize
    tmp = partial_path(target)
    try:
        group = zarr.open_group(store=str(tmp), mode="w", zarr_format=3)
        writer = LevelWriter(group, shape, arr.dtype, arr.compressors, chunk_bytes)
        for t in track(range(shape[0]), shape[0], "building levels", progress):
            sel = (t,)
            writer.add(t, checked_read(p, arr, lambda s=sel: arr[s], sel))
        writer.finish()
        replace(tmp, target)  # an exchange when levels exist (force)
    except BaseException:
        remove_path(tmp)
        raise
    return levels_summary(str(p), shape, 1 + len(writer.shapes), "rebuilt" if force else "added")


def _open_data(p: Path) -> zarr.Array:
    """The checked ``data`` array of the chronocl store at `p` (zarr v3), read-only."""
    require_store(p)
    store = CheckedStore(p)
    try:
        node = zarr.open_group(store=store, mode="r")
        arr = node["data"]
        attrs = dict(node.attrs).get("chronocl")
    except Exception:
        raise StoreFormatError(
            f"{str(p)!r} is not a chronocl store; ingest your data with 'chronocl ingest'"
        ) from None
    if not isinstance(attrs, dict) or attrs.get("format") != FORMAT:
        raise StoreFormatError(
            f"{str(p)!r} is not a chronocl store (no chronocl statistics); "
            "ingest it with 'chronocl ingest'"
        )
    if node.metadata.zarr_format != 3:
        raise StoreFormatError(
            f"{str(p)!r} is a zarr v2 store; levels are added to zarr v3 stores: "
            "ingest it again with 'chronocl ingest'"
        )
    checked_attrs(p, arr, attrs)
    store.complete = attrs.get("chunks") == "complete"
    return arr
