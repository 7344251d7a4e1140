"""Rendering: a moderngl raycaster (headless EGL), parallel views, PNG and video output.

image = chronocl.render(chronovolume, camera=Camera(azimuth=30), size=(512, 512))
image.save("view.png")     # in Jupyter, `image` displays inline
render(chronovolume, shading=True)   # lit from the camera (Shading(...) to tune it)
"""

from chronocl.render.camera import Camera
from chronocl.render.image import Image
from chronocl.render.shading import Shading
from chronocl.render.views import render, render_views

__all__ = ["Camera", "Image", "Shading", "render", "render_views"]
