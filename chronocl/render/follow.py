"""Silhouettes that follow the camera in Python: `render(cv, camera)` of a chronovolume whose
silhouette enhancement was taken along another view integrates it again along the camera's.

A silhouette depends on the view (DESIGN.md, enhancement), so a chronovolume made with
`Enhance("silhouette", view=...)` is right only from that view. The chronovolume records the
store it came from (metadata "store", with its steps, level, engine and spec); when that store
can still be opened, `following` integrates the same steps along the camera's view. Otherwise
(an in-memory series, a moved or changed store) it warns once per call, naming
`Enhance(view=...)`, and the chronovolume is drawn as it is.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from chronocl.core.errors import ChronoclError
from chronocl.data.chronovolume import Chronovolume
from chronocl.data.series import open_series
from chronocl.integration.inmemory import integrate
from chronocl.render.camera import Camera

VIEW_TOLERANCE = 1e-6  # views closer than this (unit vectors) count as the same


def stale(cv: Chronovolume, camera: Camera) -> bool:
    """Whether `cv` has a silhouette enhancement taken along another view than `camera`'s."""
    enhance = cv.metadata.get("spec", {}).get("enhance", {})
    if enhance.get("kind") != "silhouette":
        return False
    view = np.asarray(enhance.get("view", (0.0, 0.0, 1.0)), dtype=np.float64)
    return not np.allclose(view, camera.view_direction(), atol=VIEW_TOLERANCE)


def reintegrated(cv: Chronovolume, camera: Camera) -> Chronovolume | None:
    """`cv` integrated again with its silhouette along `camera`'s view, from the store it
    records; None when that store cannot be reached (or no longer matches)."""
    store = cv.metadata.get("store")
    if not store or not Path(store).exists():
        return None
    try:
        series = open_series(store)
        spec = cv.spec
        spec = replace(spec, enhance=replace(spec.enhance, view=camera.view_direction()))
        out = integrate(
            series,
            list(cv.steps),
            spec=spec,
            engine=cv.metadata.get("engine", "opencl"),
            level=int(cv.metadata.get("level", 0)),
            device_format=cv.metadata.get("device_format", "auto"),
        )
    except (ChronoclError, OSError):
        return None
    return out if out.shape == cv.shape else None


def following(chronovolumes: Sequence[Chronovolume], camera: Camera) -> list[Chronovolume]:
    """The chronovolumes with every stale silhouette integrated again along `camera`'s view
    where its store is reachable; one warning for those that are not."""
    out, unreachable = [], 0
    for cv in chronovolumes:
        if stale(cv, camera):
            again = reintegrated(cv, camera)
            unreachable += again is None
            cv = again if again is not None else cv
        out.append(cv)
    if unreachable:
        warnings.warn(
            f"{unreachable} chronovolume(s) have a silhouette enhancement taken along another "
            "view than the camera's and their series store cannot be reached to integrate "
            "them again; integrate with Enhance('silhouette', view=camera.view_direction()) "
            "to draw the silhouettes this camera sees",
            UserWarning,
            stacklevel=3,
        )
    return out
