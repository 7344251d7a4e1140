"""Interactive chronovolume viewer in the browser, rendered where the data live.

`chronocl view STORE...` serves a page (static HTML/JS/CSS from `static/`) and one WebSocket
per client: the page sends camera, window and transfer-function changes; the server
integrates (OpenCL) and raycasts (moderngl on EGL) the newest state and streams JPEG frames
back. See `server` (HTTP, token, sockets), `protocol` (message schemas) and `state` (the
per-client render worker).
"""

from chronocl.viewer.server import ViewerServer, make_app, serve

__all__ = ["ViewerServer", "make_app", "serve"]
