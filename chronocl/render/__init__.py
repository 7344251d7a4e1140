"""Rendering: a moderngl raycaster (headless EGL), parallel views, PNG and video output.

image = chronocl.render(chronovolume, camera=Camera(azimuth=30), size=(512, 512))
image.save("view.png")     # in Jupyter, `image` displays inline
"""

from chronocl.render.camera import Camera
from chronocl.render.image import Image
from chronocl.render.views import render, render_views

__all__ = ["Camera", "Image", "render", "render_views"]
