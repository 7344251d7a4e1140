"""Writing frames as a video (MP4, WebM, MKV) or an animated GIF with imageio, atomically.

Each format is written by a plugin named here (GIF: Pillow's; the others: imageio-ffmpeg's
ffmpeg), not the one imageio picks: where the ffmpeg plugin cannot load, imageio falls back on
any plugin that takes the file, and tifffile's then failed on `fps` (an internal error). A
missing or broken imageio-ffmpeg is one line naming its install (`check_video_writer`), checked
with the output path before any frame is drawn.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronocl.core.atomic import atomic_file
from chronocl.core.errors import ChronoclError, InvalidParameterError

VIDEO_SUFFIXES = (".mp4", ".gif", ".webm", ".mkv")
CODECS = {".mp4": "libx264", ".mkv": "libx264", ".webm": "libvpx-vp9"}  # ffmpeg's, by suffix
FFMPEG_INSTALL = "pip install imageio-ffmpeg"


class VideoWriterUnavailableError(ChronoclError, ImportError):
    """The library that writes a video format (imageio-ffmpeg) is missing or broken."""


def check_video_path(path: str | os.PathLike, what: str = "video") -> Path:
    """`path` if its suffix names a video format imageio writes and its writer is installed
    (`check_video_writer`), else a one-line error."""
    target = Path(path)
    if target.suffix.lower() not in VIDEO_SUFFIXES:
        raise InvalidParameterError(
            f"{what} {target.name!r}: use a video suffix ({', '.join(VIDEO_SUFFIXES)})"
        )
    check_video_writer(target.suffix)
    return target


def check_video_writer(suffix: str) -> None:
    """Nothing where the writer of `suffix` (".mp4", ...) can run, else
    VideoWriterUnavailableError naming the install: a GIF is Pillow's (a dependency), the other
    formats need imageio-ffmpeg and the ffmpeg it finds (its own, or IMAGEIO_FFMPEG_EXE)."""
    suffix = suffix.lower()
    if suffix == ".gif":
        return
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except ImportError:
        why = "which is not installed"
    except Exception as exc:  # a broken install: no ffmpeg found, or it does not run
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        why = f"which cannot find a working ffmpeg ({first})"
    else:
        return
    raise VideoWriterUnavailableError(
        f"writing a {suffix} video needs imageio-ffmpeg, {why}; install it with {FFMPEG_INSTALL}"
    )


def write_video(
    images: Sequence[np.ndarray], path: str | os.PathLike, fps: int = 12, overwrite: bool = True
) -> Path:
    """Write RGB(A) uint8 frames of one size to `path` (its suffix picks the format)."""
    import imageio.v3 as iio

    target = check_video_path(path)
    suffix = target.suffix.lower()
    with atomic_file(target, overwrite=overwrite) as tmp:
        if suffix == ".gif":
            gif = {"duration": 1000 / fps, "loop": 0}
            iio.imwrite(tmp, list(images), plugin="pillow", extension=".gif", **gif)
        else:  # H.264 and friends want even frame sizes
            even = [_pad_even(image) for image in images]
            # padded even, so no resize to 16-pixel blocks; WebM takes VP9 (asked for H.264,
            # ffmpeg wrote an empty WebM file and imageio raised nothing)
            options = {"codec": CODECS[suffix], "macro_block_size": 1}
            iio.imwrite(tmp, even, plugin="FFMPEG", extension=suffix, fps=fps, **options)
    return target


def _pad_even(image: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    return np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
