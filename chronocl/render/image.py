"""A rendered image: an (H, W, 3) uint8 array that saves as PNG and shows inline in Jupyter."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_file


@dataclass
class Image:
    """Top-down RGB image."""

    array: np.ndarray

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return self.array.shape[1], self.array.shape[0]

    def to_pil(self):
        from PIL import Image as PILImage

        return PILImage.fromarray(self.array)

    def png_bytes(self) -> bytes:
        buf = io.BytesIO()
        self.to_pil().save(buf, format="PNG")
        return buf.getvalue()

    def _repr_png_(self) -> bytes:
        return self.png_bytes()

    def save(self, path: str | os.PathLike, overwrite: bool = True) -> Path:
        """Write a PNG (or any format Pillow knows by the suffix), atomically."""
        target = Path(path)
        with atomic_file(target, overwrite=overwrite) as tmp:
            self.to_pil().save(tmp, format=_format_of(target))
        return target


def _format_of(path: Path) -> str:
    from PIL import Image as PILImage

    suffix = path.suffix.lower()
    PILImage.init()
    return PILImage.EXTENSION.get(suffix, "PNG")
