"""Writing frames as a video (MP4, WebM, MKV) or an animated GIF with imageio, atomically."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_file
from chronocl.core.errors import InvalidParameterError

VIDEO_SUFFIXES = (".mp4", ".gif", ".webm", ".mkv")


def check_video_path(path: str | os.PathLike, what: str = "video") -> Path:
    """`path` if its suffix names a video format imageio writes, else a one-line error."""
    target = Path(path)
    if target.suffix.lower() not in VIDEO_SUFFIXES:
        raise InvalidParameterError(
            f"{what} {target.name!r}: use a video suffix ({', '.join(VIDEO_SUFFIXES)})"
        )
    return target


def write_video(
    images: Sequence[np.ndarray], path: str | os.PathLike, fps: int = 12, overwrite: bool = True
) -> Path:
    """Write RGB(A) uint8 frames of one size to `path` (its suffix picks the format)."""
    import imageio.v3 as iio

    target = check_video_path(path)
    suffix = target.suffix.lower()
    with atomic_file(target, overwrite=overwrite) as tmp:
        if suffix == ".gif":
            iio.imwrite(tmp, list(images), extension=".gif", duration=1000 / fps, loop=0)
        else:  # H.264 and friends want even frame sizes
            even = [_pad_even(image) for image in images]
            options = {"codec": "libx264", "macro_block_size": 1} if suffix == ".mp4" else {}
            iio.imwrite(tmp, even, extension=suffix, fps=fps, **options)
    return target


def _pad_even(image: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    return np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
