"""The orbit camera: azimuth and elevation around what it frames, zoom, field of view, up axis.

World space: the volume box, in the data's own axes, centred at the origin, its longest side
of length 1 (voxel spacing honoured). `up` names the data axis that points up on the screen
at elevation 0; azimuth turns around it. At azimuth = elevation = 0 the first other axis (in
x, y, z order) points right and the last towards or away from the viewer, as a right-handed
frame has it (`UP_BASES`): up y (the default) has x right and z towards the viewer; up z has
x right and y away from the viewer (the viewer on the -y side); up x has y right and z away.
The camera frames the whole box, or (`frame="visible"`, the default) a `focus` box: the part of
the volume that is not transparent, which `chronocl.render.framing` finds and fills in before
drawing. It orbits about the centre of what it frames; zoom 1 fits that box's bounding sphere.
Matrices are numpy float64, row-major; upload them transposed (GL is column-major).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from chronocl.core.errors import InvalidParameterError, UnknownNameError

PROJECTIONS = ("perspective", "orthographic")
FRAMES = ("visible", "box")  # what zoom 1 fits: the non-transparent region, or the whole box
MIN_ZOOM, MAX_ZOOM = 0.01, 100.0  # beyond, the volume is a dot or the view is inside one voxel
UP_AXES = ("x", "y", "z")
# For each up axis, the data axes (rows) that point right, up and towards the viewer at
# azimuth = elevation = 0: a rotation, so `up z` draws what `up y` draws of the data turned
# to put z where y was.
UP_BASES = {
    "x": np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]),
    "y": np.eye(3),
    "z": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}


@dataclass(frozen=True)
class Camera:
    """Orbit camera. `zoom` > 1 magnifies; `view_height` (world units) fixes an orthographic
    view's height exactly, for pixel-exact views. `up` (x, y or z) is the data axis that
    points up on the screen at elevation 0, the axis azimuth turns around.

    `frame="visible"` frames `focus`, a world box (x0, y0, z0, x1, y1, z1), when it is set
    (`render` sets it to the visible region of what it draws); `frame="box"` always frames
    the whole volume box."""

    azimuth: float = 30.0
    elevation: float = 20.0
    zoom: float = 1.0
    fov: float = 30.0
    projection: str = "perspective"
    view_height: float | None = None
    frame: str = "visible"
    focus: tuple[float, float, float, float, float, float] | None = None
    up: str = "y"

    def __post_init__(self) -> None:
        for name in ("azimuth", "elevation", "zoom", "fov"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise InvalidParameterError(
                    f"camera {name} is {value!r}; give a finite number (degrees for angles)"
                )
        if not MIN_ZOOM <= self.zoom <= MAX_ZOOM:
            raise InvalidParameterError(
                f"camera zoom is {self.zoom:g}; use {MIN_ZOOM:g} to {MAX_ZOOM:g} "
                "(1 fits the volume, > 1 magnifies)"
            )
        if not 1.0 <= self.fov <= 120.0:
            raise InvalidParameterError(f"camera fov is {self.fov}; use 1 to 120 degrees")
        if self.projection not in PROJECTIONS:
            raise UnknownNameError(
                f"unknown projection {self.projection!r}; choose perspective or orthographic"
            )
        if self.view_height is not None and not (
            math.isfinite(self.view_height) and self.view_height > 0
        ):
            raise InvalidParameterError(f"view_height is {self.view_height}; it must be > 0")
        if self.up not in UP_AXES:
            raise UnknownNameError(
                f"unknown up axis {self.up!r}; choose x, y or z (the data axis that points "
                "up on the screen)"
            )
        if self.frame not in FRAMES:
            raise UnknownNameError(
                f"unknown frame {self.frame!r}; choose visible (the non-transparent region) "
                "or box (the whole volume)"
            )
        if self.focus is not None:
            box = np.asarray(self.focus, dtype=np.float64)
            if box.shape != (6,) or not np.isfinite(box).all() or not (box[3:] > box[:3]).all():
                raise InvalidParameterError(
                    f"camera focus {self.focus!r} must be a world box x0,y0,z0,x1,y1,z1 "
                    "with x0 < x1, y0 < y1, z0 < z1"
                )
            object.__setattr__(self, "focus", tuple(float(v) for v in box))

    def orbited(self, degrees: float) -> Camera:
        """The same camera turned `degrees` further in azimuth (for turntables)."""
        return replace(self, azimuth=self.azimuth + degrees)

    def eye_direction(self) -> np.ndarray:
        """Unit vector from the centre towards the eye, in data axes (x, y, z)."""
        return UP_BASES[self.up].T @ self._orbit_direction()

    def _orbit_direction(self) -> np.ndarray:
        # The eye direction in the up basis (right, up, towards the viewer at 0, 0).
        az, el = math.radians(self.azimuth), math.radians(self.elevation)
        return np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])

    def screen_axes(self) -> np.ndarray:
        """Rows: the unit vectors (data axes x, y, z) that point right, up and towards the
        eye on the screen; the view's rotation, which the axis triad draws."""
        return look_at(self.eye_direction(), np.zeros(3), self._up_vector())[:3, :3]

    def _up_vector(self) -> np.ndarray:
        # Looking straight down or up the up axis, it is parallel to the view: the axis
        # towards the viewer at azimuth 0 stands in for it.
        basis = UP_BASES[self.up]
        y = self._orbit_direction()[1]
        return -basis[2] if y > 0.999 else basis[2] if y < -0.999 else basis[1]

    def view_direction(self) -> tuple[float, float, float]:
        """Unit viewing direction (eye towards the centre), for silhouette enhancement."""
        return tuple(float(c) for c in -self.eye_direction())  # type: ignore[return-value]

    def target(self, extent: np.ndarray) -> tuple[np.ndarray, float]:
        """(centre, radius) of what the camera frames in a box of world `extent`."""
        if self.frame == "visible" and self.focus is not None:
            lo, hi = np.array(self.focus[:3]), np.array(self.focus[3:])
            return (lo + hi) / 2, 0.5 * float(np.linalg.norm(hi - lo))
        return np.zeros(3), 0.5 * float(np.linalg.norm(extent))

    def matrices(self, extent: np.ndarray, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """(view, projection) for a box of world `extent` (x, y, z) and image aspect w / h."""
        centre, radius = self.target(extent)
        box_radius = 0.5 * float(np.linalg.norm(extent))
        half_fov = math.radians(self.fov) / 2
        distance = radius / math.sin(half_fov) / self.zoom
        eye = centre + self.eye_direction() * distance
        view = look_at(eye, centre, self._up_vector())
        # The whole box lies within box_radius of the origin: near and far keep all of it.
        off = float(np.linalg.norm(centre))
        near = max(distance - off - 2 * box_radius, 1e-3 * distance)
        far = distance + off + 2 * box_radius
        if self.projection == "perspective":
            proj = perspective(2 * half_fov, aspect, near, far)
        else:
            height = self.view_height if self.view_height is not None else 2 * radius / self.zoom
            proj = orthographic(height * aspect, height, near, far)
        return view, proj


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    f = target - eye
    f = f / np.linalg.norm(f)
    s = np.cross(f, up)
    s = s / np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fovy: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(fovy / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(width: float, height: float, near: float, far: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 0], m[1, 1] = 2.0 / width, 2.0 / height
    m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return m


def world_extent(shape_zyx: tuple[int, int, int], spacing_xyz) -> np.ndarray:
    """A volume's world extent (x, y, z) as the raycaster lays it out: its longest side 1."""
    nz, ny, nx = shape_zyx
    dx, dy, dz = spacing_xyz
    physical = np.array([nx * dx, ny * dy, nz * dz], dtype=np.float64)
    return physical / physical.max()


def world_geometry(shape_zyx, spacing_xyz) -> tuple[np.ndarray, np.ndarray]:
    """A volume's `world_extent` and the world size (x, y, z) of one of its voxels."""
    nz, ny, nx = shape_zyx
    extent = world_extent((nz, ny, nx), spacing_xyz)
    return extent, extent / np.array([nx, ny, nz])


def to_panel(
    camera: Camera, extent: np.ndarray, size: tuple[int, int], world: np.ndarray
) -> np.ndarray | None:
    """Where world points (k, 3) land on a panel of `size` seen with `camera`: (k, 2) x, y
    fractions of the panel, top-left origin (beyond 0..1 off the panel); None when a point is
    behind the camera."""
    w, h = size
    view, proj = camera.matrices(extent, w / h)
    at = (proj @ view @ np.c_[world, np.ones(len(world))].T).T
    if (at[:, 3] <= 1e-9).any():
        return None
    return np.c_[(at[:, 0] / at[:, 3] + 1) / 2, (1 - at[:, 1] / at[:, 3]) / 2]
