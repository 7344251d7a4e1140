"""Chronovolume: the integrated RGBA volume, its t_index and the metadata that made it.

A viewer's frames may hold RGBA8 instead of float32 (display chronovolumes, written by the
kernels in the format the raycaster samples: `integrate_bricks(display=True)`).
Saved as a zarr v3 group: array ``rgba`` (Z, Y, X, 4) premultiplied float32,
array ``t_index`` (Z, Y, X) int32 for first_hit / max / min (-1 where no step
contributed), and attribute ``chronocl`` with the metadata (dataset,
selection, integration spec, spacing, value range).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zarr

from chronocl.core.atomic import atomic_directory
from chronocl.core.errors import InvalidSelectionError, StoreFormatError
from chronocl.core.paths import check_apart
from chronocl.core.selection import Selection
from chronocl.data.integrity import checked_read
from chronocl.data.remote_store import is_url
from chronocl.data.remote_write import remote_output
from chronocl.data.stores import open_group
from chronocl.data.writer import compressors
from chronocl.modes.spec import IntegrationSpec

FORMAT = "chronocl.chronovolume"


@dataclass
class Chronovolume:
    """Premultiplied RGBA (Z, Y, X, 4), optional t_index (Z, Y, X) and metadata."""

    rgba: np.ndarray
    t_index: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)

    def described(self, strict: bool = True) -> tuple[str, str | None, str]:
        """What its reprs (this one and the HTML summary) say of it, read from its metadata:
        the mode ('?' where none is named), the steps integrated ('0:10:3 (4 of 12)'; None
        where none are named) and the shape ('6×5×4 (x, y, z)', x first). Steps that are no
        selection (not written by chronocl) raise, or, not `strict`, are shown as they are."""
        meta = self.metadata
        spec = meta.get("spec") or {}
        sel = meta.get("selection") or {}
        steps = sel.get("steps") or []
        shown = None
        if steps:
            try:
                n = int(sel.get("n_steps", max(steps) + 1))
                shown = f"{Selection(tuple(steps), n).describe()} ({len(steps)} of {n})"
            except (InvalidSelectionError, TypeError, ValueError):
                if strict:
                    raise
                shown = f"{steps!r} (not a selection of {sel.get('n_steps', '?')} steps)"
        z, y, x = self.shape
        return str(spec.get("mode", "?")), shown, f"{x}×{y}×{z} (x, y, z)"

    def __repr__(self) -> str:
        """One line: shape, mode, steps and where it came from (not the arrays' values); steps
        that are no selection are shown as they are (the HTML summary falls back to it)."""
        meta = self.metadata
        mode, steps, shape = self.described(strict=False)
        parts = [shape, f"mode={mode}"]
        if steps:
            parts.append(f"steps {steps}")
        if meta.get("dataset"):
            parts.append(f"from {meta['dataset']!r}")
        parts.append("with t_index" if self.t_index is not None else "no t_index")
        return f"Chronovolume({', '.join(parts)})"

    def _repr_html_(self) -> str | None:
        """A notebook's summary with a small picture (`chronocl.data.repr_html`)."""
        from chronocl.data.repr_html import chronovolume_html, safe

        return safe(chronovolume_html, self)

    @property
    def shape(self) -> tuple[int, int, int]:
        """(Z, Y, X): the arrays' shape (`dims` is the same, x first)."""
        return self.rgba.shape[:3]  # type: ignore[return-value]

    @property
    def dims(self) -> tuple[int, int, int]:
        """(nx, ny, nz), x first: voxels along each axis."""
        return self.rgba.shape[2::-1]  # type: ignore[return-value]

    @property
    def rgba_dtype(self) -> np.dtype:
        """The RGBA's dtype (uint8: a display chronovolume). A viewer's GPU recolour knows it
        without reading its RGBA back from the texture (`chronocl.viewer.recolouring.InTexture`,
        which also knows `shape` and `dims`)."""
        return self.rgba.dtype

    @property
    def spec(self) -> IntegrationSpec:
        return IntegrationSpec.from_dict(self.metadata["spec"])

    @property
    def steps(self) -> tuple[int, ...]:
        return tuple(self.metadata["selection"]["steps"])

    @property
    def spacing(self) -> tuple[float, float, float]:
        """(dx, dy, dz), x first: the voxel spacing of the series it was integrated from."""
        sp = self.metadata.get("spacing", {"x": 1.0, "y": 1.0, "z": 1.0})
        return (sp["x"], sp["y"], sp["z"])

    @property
    def spacing_zyx(self) -> tuple[float, float, float]:
        """(dz, dy, dx): `spacing` in the arrays' axis order, for code indexing (Z, Y, X)."""
        return self.spacing[::-1]  # type: ignore[return-value]

    def float_rgba(self) -> np.ndarray:
        """The RGBA as float32: a display chronovolume's RGBA8 (a viewer's frame,
        `integrate_bricks(display=True)`) divided by 255, any other's as it is."""
        if self.rgba.dtype == np.uint8:
            return self.rgba.astype(np.float32) / np.float32(255)
        return np.asarray(self.rgba, dtype=np.float32)

    def check_apart_from_source(self, path: str | os.PathLike) -> None:
        """Raise OutputIsInputError where `path`, a local output, is, lies in or holds the
        series store this chronovolume was integrated from (`metadata["store"]`)."""
        source = self.metadata.get("store") or None
        if source is not None and not is_url(str(source)):
            check_apart(path, [source])

    def save(
        self, path: str | os.PathLike, overwrite: bool = False, storage_options: dict | None = None
    ) -> Path | str:
        """Write to a zarr store atomically: a local path, or an s3:// URL (published whole,
        root metadata last: `chronocl.data.remote_write`, given `storage_options`)."""
        if is_url(str(path)):
            with remote_output(str(path), overwrite, storage_options) as local:
                self.save(local)
            return str(path)
        self.check_apart_from_source(path)
        z, y, x, _ = self.rgba.shape
        zc = max(1, min(z, (8 * 2**20) // max(1, y * x * 16)))
        keep = {"compressors": compressors("zstd"), "config": {"write_empty_chunks": True}}
        with atomic_directory(path, overwrite) as tmp:
            group = zarr.open_group(store=str(tmp), mode="w", zarr_format=3)
            group.create_array("rgba", data=self.float_rgba(), chunks=(zc, y, x, 4), **keep)
            if self.t_index is not None:
                group.create_array(
                    "t_index", data=self.t_index.astype(np.int32), chunks=(zc, y, x), **keep
                )
            group.attrs["chronocl"] = {
                "format": FORMAT,
                "version": 1,
                "chunks": "complete",
                **self.metadata,
            }
        return Path(path)

    @classmethod
    def load(cls, path: str | os.PathLike, storage_options: dict | None = None) -> Chronovolume:
        """Read the chronovolume at `path`: a local path or an http(s):// or s3:// URL."""
        p = str(path).rstrip("/") if is_url(str(path)) else Path(path)
        group = open_group(p, "chronovolume", ("rgba", "t_index"), storage_options)
        attrs = dict(dict(group.attrs).get("chronocl", {}))
        if attrs.pop("format", None) != FORMAT or "rgba" not in group:
            raise StoreFormatError(
                f"{str(p)!r} is not a chronovolume (is it a series? integrate it first)"
            )
        attrs.pop("version", None)
        attrs.pop("chunks", None)  # how it was stored, not what made it
        arrays = {}
        for name in ("rgba", "t_index"):
            if name in group:
                arr = group[name]
                arrays[name] = checked_read(p, arr, lambda a=arr: np.asarray(a[...]), ())
        return cls(rgba=arrays["rgba"], t_index=arrays.get("t_index"), metadata=attrs)
