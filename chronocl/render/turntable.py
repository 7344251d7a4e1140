"""Turntable videos: the camera orbits the volume, one frame per step, written by imageio."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_file
from chronocl.core.errors import InvalidParameterError
from chronocl.core.progress import track
from chronocl.render.camera import Camera
from chronocl.render.image import Image

VIDEO_SUFFIXES = (".mp4", ".gif", ".webm", ".mkv")


def check_video(path: str | os.PathLike, frames: int) -> Path:
    """Validate a turntable's output path and frame count before any work is done."""
    target = Path(path)
    if target.suffix.lower() not in VIDEO_SUFFIXES:
        raise InvalidParameterError(
            f"turntable {target.name!r}: use a video suffix ({', '.join(VIDEO_SUFFIXES)})"
        )
    if not 2 <= frames <= 3600:
        raise InvalidParameterError(f"turntable frames is {frames}; use 2 to 3600")
    return target


def turntable(
    frame: Callable[[Camera], Image],
    camera: Camera,
    path: str | os.PathLike,
    frames: int = 36,
    fps: int = 12,
    overwrite: bool = True,
    progress: bool = False,
) -> Path:
    """Render `frames` views a full turn apart in azimuth with `frame(camera)`; write a video."""
    import imageio.v3 as iio

    target = check_video(path, frames)
    images: Sequence = [
        frame(camera.orbited(360.0 * i / frames)).array
        for i in track(range(frames), frames, "rendering frames", progress)
    ]
    suffix = target.suffix.lower()
    with atomic_file(target, overwrite=overwrite) as tmp:
        if suffix == ".gif":
            iio.imwrite(tmp, images, extension=".gif", duration=1000 / fps, loop=0)
        else:  # H.264 and friends want even frame sizes
            even = [_pad_even(image) for image in images]
            options = {"codec": "libx264", "macro_block_size": 1} if suffix == ".mp4" else {}
            iio.imwrite(tmp, even, extension=suffix, fps=fps, **options)
    return target


def _pad_even(image: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    return np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
