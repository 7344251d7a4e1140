"""Movies from the viewer: an orbit of the camera or a play-through of the window over the
series, drawn as the page shows them (every view, annotated as Save PNG annotates it: title,
captions, legends) and written as MP4 or GIF.

The worker supplies `frame(state)`, the composed image of a view state at full resolution;
this module decides the states and writes the video (chronocl.render.video).
"""

from __future__ import annotations

import dataclasses
import secrets
from collections.abc import Callable
from pathlib import Path

import numpy as np

from chronocl.core.errors import InvalidParameterError
from chronocl.render.video import check_video_writer, write_video
from chronocl.viewer.protocol import LIMITS, MOVIE_FORMATS, MOVIES
from chronocl.viewer.view_state import ViewState


def movie_states(state: ViewState, kind: str, frames: int, n_steps: int) -> list[ViewState]:
    """The view states of a movie's frames.

    orbit: `frames` cameras a full turn apart in azimuth (each view's own camera turning as
    the shared one), the window as shown. play: the
    window, keeping its length and stride, slid one stride at a time from the series' first
    step until it reaches the last (at most `LIMITS.movie_frames` positions), the camera as shown.
    """
    state = dataclasses.replace(state, quality="full")
    if kind == "orbit":
        return [
            dataclasses.replace(
                state,
                camera=state.camera.orbited(360.0 * i / frames),
                view_cameras=tuple(
                    None if c is None else c.orbited(360.0 * i / frames) for c in state.view_cameras
                ),
            )
            for i in range(frames)
        ]
    if kind != "play":
        raise InvalidParameterError(f"unknown movie {kind!r}; choose one of {', '.join(MOVIES)}")
    t0, t1, stride = state.window
    length = t1 - t0
    starts = list(range(0, max(1, n_steps - length + 1), max(1, stride)))
    if len(starts) < 2:
        raise InvalidParameterError(
            f"the window spans {length} of {n_steps} steps, so it cannot slide; "
            "shorten it to make a play-through"
        )
    starts = starts[: LIMITS.movie_frames]
    return [dataclasses.replace(state, window=(s, s + length, stride)) for s in starts]


def render_movie(
    states: list[ViewState],
    frame: Callable[[ViewState], np.ndarray],
    fmt: str,
    fps: int,
    folder: Path,
    progress: Callable[[int, int], None] = lambda done, total: None,
) -> Path:
    """Draw every state with `frame` and write them as a video in `folder`; returns its path.
    `progress(done, total)` is told after each frame."""
    if fmt not in MOVIE_FORMATS:
        raise InvalidParameterError(
            f"unknown movie format {fmt!r}; choose one of {', '.join(MOVIE_FORMATS)}"
        )
    check_video_writer(f".{fmt}")  # a missing imageio-ffmpeg: one line, before any frame
    images = []
    for i, state in enumerate(states):
        image = frame(state)
        if images and image.shape != images[0].shape:  # frames of one size, as the first
            image = _fit(image, images[0].shape)
        images.append(image)
        progress(i + 1, len(states))
    return write_video(images, Path(folder) / f"movie-{secrets.token_hex(8)}.{fmt}", fps)


def _fit(image: np.ndarray, shape: tuple) -> np.ndarray:
    out = np.zeros(shape, image.dtype)
    h, w = min(shape[0], image.shape[0]), min(shape[1], image.shape[1])
    out[:h, :w] = image[:h, :w]
    return out
