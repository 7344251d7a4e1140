"""Turntable videos: the camera orbits the volume, one frame per step, written by imageio.

`ModeViews` draws one window of a series integrated in several modes as parallel views (what
`chronocl render` writes) and turns them into a turntable. A silhouette enhancement depends on
the view, so its chronovolumes are integrated again for every frame's camera; any other set is
uploaded once and drawn from every angle.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from chronocl.core.enhance import Enhance
from chronocl.core.errors import InvalidParameterError
from chronocl.core.progress import track
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import TimeSeries
from chronocl.integration.inmemory import integrate
from chronocl.render.camera import Camera
from chronocl.render.framing import framed
from chronocl.render.image import Image
from chronocl.render.video import check_video_path, write_video
from chronocl.render.views import raycaster, render_views


def check_video(path: str | os.PathLike, frames: int) -> Path:
    """Validate a turntable's output path and frame count before any work is done."""
    target = check_video_path(path, "turntable")
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
    target = check_video(path, frames)
    images: Sequence = [
        frame(camera.orbited(360.0 * i / frames)).array
        for i in track(range(frames), frames, "rendering frames", progress)
    ]
    return write_video(images, target, fps, overwrite)


@dataclass(frozen=True)
class ModeViews:
    """One window of `series` integrated in each of `modes` and drawn as parallel views of
    `size`, with a legend (and a label per panel when there are several).

    `spec_args` are the arguments of `chronocl.make_spec` shared by every mode; `draw_args`
    those of `render_views` (background, clip, outline, axes, time_labels).
    """

    series: TimeSeries
    window: object
    modes: Sequence[str]
    size: tuple[int, int] = (512, 512)
    engine: str = "opencl"
    device: str | None = None
    spec_args: Mapping[str, object] = field(default_factory=dict)
    draw_args: Mapping[str, object] = field(default_factory=dict)
    level: int = 0  # a coarse level of the series (docs/levels.md)
    device_format: str = "auto"  # what bricks travel to the device in (engine.device_formats)
    # a `chronocl.events.colour.TrackColour`: each integrated chronovolume coloured by track
    tracks: object = None

    @property
    def follows_camera(self) -> bool:
        """Whether the chronovolumes depend on the view (a silhouette enhancement)."""
        enhance = self.spec_args.get("enhance")
        kind = enhance.kind if isinstance(enhance, Enhance) else enhance
        return kind == "silhouette"

    def integrate(self, camera: Camera) -> list[Chronovolume]:
        """The chronovolumes of every mode, a silhouette taken along `camera`'s view (coloured
        by track with `tracks`)."""
        args = dict(
            self.spec_args, engine=self.engine, device=self.device, device_format=self.device_format
        )
        if self.follows_camera:
            enhance = args["enhance"]
            view = camera.view_direction()
            args["enhance"] = (
                replace(enhance, view=view)
                if isinstance(enhance, Enhance)
                else Enhance(str(enhance), view=view)
            )
        cvs = [integrate(self.series, self.window, m, level=self.level, **args) for m in self.modes]
        return cvs if self.tracks is None else self.tracks.apply(cvs)  # type: ignore[attr-defined]

    def draw(self, chronovolumes: Sequence[Chronovolume], camera: Camera, volumes=None) -> Image:
        """The parallel views of `chronovolumes` (`volumes`: them uploaded, if they are)."""
        return render_views(
            chronovolumes,
            camera,
            self.size,
            legend=True,
            labels=None if len(chronovolumes) > 1 else [],
            volumes=volumes,
            **self.draw_args,  # type: ignore[arg-type]
        )

    def turntable(
        self,
        chronovolumes: Sequence[Chronovolume],
        camera: Camera,
        path: str | os.PathLike,
        frames: int = 36,
        overwrite: bool = True,
        progress: bool = False,
    ) -> Path:
        """A full turn from `camera` as a video: `chronovolumes` (as `integrate(camera)` made
        them) uploaded once and drawn from every angle, or integrated again for every frame's
        view when they follow the camera. Every frame frames what `camera` frames for them."""
        camera = framed(camera, chronovolumes)  # once: re-integrated frames keep one focus
        follows = self.follows_camera
        volumes = [] if follows else [raycaster().upload(cv) for cv in chronovolumes]

        def frame(cam: Camera) -> Image:
            if follows:
                return self.draw(self.integrate(cam), cam)
            return self.draw(chronovolumes, cam, volumes)

        try:
            return turntable(
                frame, camera, path, frames=frames, overwrite=overwrite, progress=progress
            )
        finally:
            for volume in volumes:
                volume.release()
