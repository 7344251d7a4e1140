"""Interactive chronovolume viewer in the browser, rendered where the data live.

`chronocl view STORE...` serves a page (static HTML, ES modules and CSS from `static/`) and one
WebSocket per client: the page sends camera, window and transfer-function changes; the server
integrates (OpenCL) and raycasts (moderngl on EGL) the newest state and streams JPEG frames
back. The modules, outermost first:

- `server` (`ViewerServer`, `serve`: options, binding, uvicorn), `app` (routes, static files,
  client cap), `guard` (Host, token, Origin), `heap` (memory keeper);
- `sockets` (one client's socket: the `info` message, the protocol loop), `protocol` (message
  schemas and the choices the page is sent; primitives in `schema`);
- `worker` (the per-client render thread), `view_state` (the desired state and its merging),
  `snapshot` (the saved state: a versioned JSON file, Save session, `render --state`),
  `slots` (a panel's session and texture), `frames` (encoding, legend), `probe`, `saving`
  (downloads), `datasets`, `gl_thread`, `errors`.
"""

from chronocl.viewer.app import make_app
from chronocl.viewer.server import ViewerServer, serve

__all__ = ["ViewerServer", "make_app", "serve"]
