"""A rendered image: an (H, W, 3) uint8 array that saves as PNG and shows inline in Jupyter;
its `text` (e.g. Title, Description) goes into a PNG's text chunks."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_file


@dataclass
class Image:
    """Top-down RGB image."""

    array: np.ndarray
    text: dict[str, str] = field(default_factory=dict)  # PNG text chunks (keyword: text)

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return self.array.shape[1], self.array.shape[0]

    def to_pil(self):
        from PIL import Image as PILImage

        return PILImage.fromarray(self.array)

    def png_bytes(self) -> bytes:
        buf = io.BytesIO()
        self.to_pil().save(buf, format="PNG", **self._png_info())
        return buf.getvalue()

    def _repr_png_(self) -> bytes:
        return self.png_bytes()

    def save(self, path: str | os.PathLike, overwrite: bool = True) -> Path:
        """Write a PNG (or any format Pillow knows by the suffix), atomically."""
        target = Path(path)
        with atomic_file(target, overwrite=overwrite) as tmp:
            fmt = _format_of(target)
            self.to_pil().save(tmp, format=fmt, **(self._png_info() if fmt == "PNG" else {}))
        return target

    def _png_info(self) -> dict:
        if not self.text:
            return {}
        from PIL.PngImagePlugin import PngInfo

        info = PngInfo()
        for key, value in self.text.items():
            info.add_itxt(key, value)  # international text: any characters
        return {"pnginfo": info}


def _format_of(path: Path) -> str:
    from PIL import Image as PILImage

    suffix = path.suffix.lower()
    PILImage.init()
    return PILImage.EXTENSION.get(suffix, "PNG")
