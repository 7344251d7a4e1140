"""The viewer's ASGI application: the page and its static assets, downloads, the WebSocket
route (at most `max_clients` at once; the next one is told so and closed) and the memory
keeper, all behind the `TokenGuard`."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
from importlib import resources

from chronocl.core import process_memory
from chronocl.core.budget import parse_memory
from chronocl.core.process_memory import ProcessLimit
from chronocl.core.tuning import TUNING
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.errors import internal_error, log
from chronocl.viewer.guard import TokenGuard
from chronocl.viewer.heap import HeapKeeper
from chronocl.viewer.protocol import LIMITS
from chronocl.viewer.saving import Downloads
from chronocl.viewer.sockets import serve_socket
from chronocl.viewer.view_sessions import SharedSteps

MEDIA_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
}
CLOSE_TRY_AGAIN = 1013  # WebSocket close code: try again later


def static_folder():
    return resources.files("chronocl.viewer") / "static"


def static_files() -> dict[str, str]:
    """The page's files (static/: HTML, its ES modules, CSS), by name, with media types."""
    return {
        f.name: MEDIA_TYPES[os.path.splitext(f.name)[1]]
        for f in static_folder().iterdir()
        if os.path.splitext(f.name)[1] in MEDIA_TYPES
    }


STATIC = static_files()


def static_file(name: str) -> bytes:
    return (static_folder() / name).read_bytes()


def make_app(
    datasets: list[Dataset],
    token: str,
    *,
    engine: str = "opencl",
    device: str | None = None,
    memory: str | int | None = None,
    downloads: Downloads | None = None,
    max_clients: int = LIMITS.clients,
    host: str = "127.0.0.1",
    port: int | None = None,
):
    """The ASGI application (Host- and token-guarded Starlette app). At most `max_clients`
    sockets are served at once; `host`/`port` are where the server listens (the Host check)."""
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, PlainTextResponse, Response
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocket, WebSocketDisconnect

    downloads = downloads or Downloads()
    heap = HeapKeeper()
    active = 0  # sockets being served (only the event loop's thread touches it)

    async def index(request):
        return Response(static_file("index.html"), media_type=STATIC["index.html"])

    async def static(request):
        name = request.path_params["name"]
        if name not in STATIC:
            return PlainTextResponse("not found", status_code=404)
        return Response(static_file(name), media_type=STATIC[name])

    async def download(request):
        item = downloads.get(request.path_params["key"])
        if item is None:
            return PlainTextResponse("no such download (they expire); save again", 404)
        path, filename, media_type = item
        return FileResponse(path, media_type=media_type, filename=filename)

    async def refuse_over_cap(websocket: WebSocket) -> None:
        message = (
            f"the viewer already serves {max_clients} connections, its limit; close another "
            "tab or start 'chronocl view' with a larger --max-clients"
        )
        with contextlib.suppress(Exception):  # the client may be gone already
            await websocket.accept()
            await websocket.send_text(json.dumps({"type": "error", "id": None, "message": message}))
            await websocket.close(CLOSE_TRY_AGAIN, "too many connections")

    async def socket_endpoint(websocket: WebSocket) -> None:
        nonlocal active
        if active >= max_clients:
            await refuse_over_cap(websocket)
            return
        active += 1  # no await between the test and the count
        try:
            await serve_socket(
                websocket,
                datasets,
                downloads,
                engine=engine,
                device=device,
                memory=memory,
                shared=shared,
            )
        except WebSocketDisconnect:
            pass
        except Exception as exc:  # a bug: its line and traceback in the log; the server goes on
            log.error("chronocl viewer: %s", internal_error(exc, "on a socket"), exc_info=exc)
        finally:
            active -= 1

    async def keep_heap() -> None:
        while True:
            await asyncio.sleep(TUNING.heap_check_s)
            await asyncio.to_thread(heap.check)

    # One memory limit for the whole process, every client's steps and frames within it, and
    # one set of resident steps that every client's views read.
    limit = None if memory is None else ProcessLimit(parse_memory(memory))
    shared = SharedSteps()

    @contextlib.asynccontextmanager
    async def lifespan(app):
        heap.freeze()
        keeper = asyncio.create_task(keep_heap())
        try:
            with process_memory.limited(limit):
                yield
        finally:
            keeper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await keeper
            heap.unfreeze()
            downloads.close()
            await asyncio.to_thread(shared.close)

    app = Starlette(
        routes=[
            Route("/", index),
            Route("/static/{name}", static),
            Route("/download/{key}", download),
            WebSocketRoute("/ws", socket_endpoint),
        ],
        lifespan=lifespan,
    )
    guard = TokenGuard(app, token, host=host, port=port)
    guard.heap = heap  # type: ignore[attr-defined]  # its counters, for benchmarks
    return guard
