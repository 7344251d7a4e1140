"""The viewer's web server: the page, its assets, downloads and one WebSocket per client.

Starlette on uvicorn. Every request needs the server's random token: `?token=` in the URL
(the page then gets it as a cookie), the cookie, an `X-Chronocl-Token` header or
`Authorization: Bearer`; tokens are compared with `hmac.compare_digest`. A WebSocket whose
`Origin` is not the host it connected to is refused. The client names data sets only by
index or name from the list the server was started with.

    server = ViewerServer(["vortex.zarr"])   # 127.0.0.1, a free port
    print(server.url)                        # http://127.0.0.1:PORT/?token=...
    server.run()                             # or start() / stop() on a thread
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import os
import secrets
import socket
import sys
import threading
from collections.abc import Sequence
from http.cookies import SimpleCookie
from importlib import resources
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

from ..errors import ChronoclError, InvalidParameterError
from .protocol import MAX_MESSAGE_BYTES, MAX_VIEWS, ProtocolError, parse_message, request_id
from .state import ClientWorker, Dataset, Downloads

STATIC = {
    "index.html": "text/html; charset=utf-8",
    "app.js": "text/javascript; charset=utf-8",
    "style.css": "text/css; charset=utf-8",
}
LOOPBACK = ("127.0.0.1", "localhost", "::1")
CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self'; form-action 'none'; frame-ancestors 'none'; base-uri 'none'"
)
SEND_TIMEOUT_S = 60.0


def static_file(name: str) -> bytes:
    return (resources.files("chronocl.viewer") / "static" / name).read_bytes()


def open_datasets(stores: Sequence[str | os.PathLike]) -> list[Dataset]:
    """Open each store; names are the stores' stems, made unique with a suffix."""
    from ..data.series import open_series

    if not stores:
        raise InvalidParameterError("no store given; name at least one series store to view")
    datasets: list[Dataset] = []
    seen: set[str] = set()
    for store in stores:
        series = open_series(store)
        base = Path(store).name.removesuffix(".zarr") or "series"
        name, n = base, 2
        while name in seen:
            name, n = f"{base}-{n}", n + 1
        seen.add(name)
        datasets.append(Dataset(name, series))
    return datasets


class TokenGuard:
    """ASGI middleware: the token on every request, the Origin on sockets, safe headers."""

    def __init__(self, app, token: str) -> None:
        self.app = app
        self.token = token.encode()

    def cookie_name(self, scope) -> str:
        port = (scope.get("server") or ("", 0))[1]
        return f"chronocl_token_{port}"

    def _offered(self, scope, headers: dict[str, str]) -> tuple[list[str], bool]:
        """Tokens the request offers, and whether one came in the query string."""
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        from_query = query.get("token", [])
        offered = list(from_query)
        if "x-chronocl-token" in headers:
            offered.append(headers["x-chronocl-token"])
        auth = headers.get("authorization", "")
        if auth.lower().startswith("bearer "):
            offered.append(auth[7:].strip())
        if "cookie" in headers:
            jar: SimpleCookie = SimpleCookie()
            with contextlib.suppress(Exception):
                jar.load(headers["cookie"])
            morsel = jar.get(self.cookie_name(scope))
            if morsel is not None:
                offered.append(morsel.value)
        return offered, bool(from_query)

    def _valid(self, offered: list[str]) -> bool:
        ok = False
        for t in offered:
            ok |= hmac.compare_digest(t.encode("utf-8", "replace"), self.token)
        return ok

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        offered, from_query = self._offered(scope, headers)
        if not self._valid(offered):
            await self._refuse(scope, send, "the token is missing or wrong")
            return
        if scope["type"] == "websocket":
            origin = headers.get("origin")
            if origin is not None and urlsplit(origin).netloc != headers.get("host", ""):
                await self._refuse(scope, send, "the page's origin is not this server")
                return
            await self.app(scope, receive, send)
            return

        cookie = None
        if from_query:
            cookie = (
                f"{self.cookie_name(scope)}={self.token.decode()}; Path=/; HttpOnly; "
                "SameSite=Strict"
            )

        async def send_with_headers(message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                headers += [
                    (b"x-content-type-options", b"nosniff"),
                    (b"referrer-policy", b"no-referrer"),
                    (b"cache-control", b"no-store"),
                    (b"content-security-policy", CSP.encode()),
                ]
                if cookie:
                    headers.append((b"set-cookie", cookie.encode()))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)

    async def _refuse(self, scope, send, why: str) -> None:
        if scope["type"] == "websocket":
            # Closing before accepting makes the server answer the handshake with 403.
            await send({"type": "websocket.close", "code": 1008, "reason": why})
            return
        body = (
            f"403 forbidden: {why}; open the URL with ?token=... that 'chronocl view' printed\n"
        ).encode()
        await send(
            {
                "type": "http.response.start",
                "status": 403,
                "headers": [
                    (b"content-type", b"text/plain; charset=utf-8"),
                    (b"content-length", str(len(body)).encode()),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})


def make_app(
    datasets: list[Dataset],
    token: str,
    *,
    engine: str = "opencl",
    device: str | None = None,
    memory: str | int | None = None,
    downloads: Downloads | None = None,
):
    """The ASGI application (token-guarded Starlette app)."""
    from starlette.applications import Starlette
    from starlette.responses import FileResponse, PlainTextResponse, Response
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocket, WebSocketDisconnect

    downloads = downloads or Downloads()

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

    async def socket_endpoint(websocket: WebSocket) -> None:
        await websocket.accept()
        loop = asyncio.get_running_loop()
        send_lock = asyncio.Lock()
        gone = threading.Event()

        async def deliver(data: str | bytes) -> None:
            async with send_lock:
                if isinstance(data, bytes):
                    await websocket.send_bytes(data)
                else:
                    await websocket.send_text(data)

        def send_from_thread(data: str | bytes) -> bool:
            if gone.is_set():
                return False
            try:
                asyncio.run_coroutine_threadsafe(deliver(data), loop).result(SEND_TIMEOUT_S)
            except Exception:  # closed socket, cancelled, timed out: the client is gone
                gone.set()
                return False
            return True

        worker = ClientWorker(
            datasets, send_from_thread, downloads, engine=engine, device=device, memory=memory
        )
        try:
            await deliver(
                json.dumps(
                    {
                        "type": "info",
                        "datasets": [
                            {"index": i, "name": d.name, "shape": list(d.series.shape)}
                            for i, d in enumerate(datasets)
                        ],
                        "limits": {
                            "max_views": MAX_VIEWS,
                            "max_message_bytes": MAX_MESSAGE_BYTES,
                        },
                    }
                )
            )
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                try:
                    if text is None:
                        raise ProtocolError("binary messages are not accepted; send JSON text")
                    msg = parse_message(text)
                    reply = handle(worker, msg)
                    if reply is not None:
                        await deliver(json.dumps(reply))
                except ChronoclError as exc:
                    await deliver(
                        json.dumps({"type": "error", "id": request_id(text), "message": str(exc)})
                    )
        except WebSocketDisconnect:
            pass
        finally:
            gone.set()
            worker.close()

    @contextlib.asynccontextmanager
    async def lifespan(app):
        yield
        downloads.close()

    app = Starlette(
        routes=[
            Route("/", index),
            Route("/static/{name}", static),
            Route("/download/{key}", download),
            WebSocketRoute("/ws", socket_endpoint),
        ],
        lifespan=lifespan,
    )
    return TokenGuard(app, token)


def handle(worker: ClientWorker, msg: dict) -> dict | None:
    """Apply one validated message; returns an immediate reply, if any."""
    kind = msg["type"]
    if kind == "open":
        return {
            "type": "dataset",
            "id": msg.get("id"),
            **worker.open(msg["dataset"], msg.get("id")),
        }
    if kind == "update":
        worker.update(msg)
        return None
    worker.task(kind, msg)
    return None


class ViewerServer:
    """`chronocl view`: serve the given stores on host:port (port 0: a free one)."""

    def __init__(
        self,
        stores: Sequence[str | os.PathLike] | None = None,
        *,
        datasets: list[Dataset] | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        token: str | None = None,
        engine: str = "opencl",
        device: str | None = None,
        memory: str | int | None = None,
    ) -> None:
        import uvicorn

        self.datasets = datasets if datasets is not None else open_datasets(stores or [])
        self.token = token or secrets.token_urlsafe(24)
        self.host = host
        if not 0 <= port <= 65535:
            raise InvalidParameterError(f"port {port} is outside 0..65535; use 0 for a free one")
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise InvalidParameterError(
                f"cannot listen on {host}:{port} ({exc.strerror}); choose another --port or 0"
            ) from None
        self.sock.listen(128)  # connections wait in the backlog until uvicorn accepts
        self.port = self.sock.getsockname()[1]
        self.downloads = Downloads()
        app = make_app(
            self.datasets,
            self.token,
            engine=engine,
            device=device,
            memory=memory,
            downloads=self.downloads,
        )
        config = uvicorn.Config(
            app,
            log_level="warning",
            ws_max_size=4 * MAX_MESSAGE_BYTES,
            ws_per_message_deflate=False,
            lifespan="on",
        )
        self.server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    @property
    def base(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    @property
    def url(self) -> str:
        return f"{self.base}/?token={self.token}"

    def warn_if_exposed(self) -> str | None:
        if self.host in LOOPBACK:
            return None
        return (
            f"warning: serving on {self.host}, reachable from other machines; anyone with the "
            "token can view these data. Prefer the default 127.0.0.1 and 'ssh -L' forwarding."
        )

    def run(self) -> None:
        """Serve until interrupted (Ctrl-C)."""
        self.server.run(sockets=[self.sock])

    def start(self, timeout: float = 30.0) -> str:
        """Serve on a background thread; returns the URL once listening."""
        self._thread = threading.Thread(target=self.run, name="chronocl-viewer", daemon=True)
        self._thread.start()
        deadline = timeout
        while not self.server.started and deadline > 0:
            threading.Event().wait(0.02)
            deadline -= 0.02
        if not self.server.started:
            raise RuntimeError("the viewer server did not start")
        return self.url

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(10)
        self.sock.close()
        self.downloads.close()


def serve(
    stores: Sequence[str | os.PathLike],
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    open_browser: bool = True,
    engine: str = "opencl",
    device: str | None = None,
    memory: str | int | None = None,
) -> None:
    """Run the viewer: print the URL (with its token), open the browser, serve until Ctrl-C."""
    server = ViewerServer(stores, host=host, port=port, engine=engine, device=device, memory=memory)
    warning = server.warn_if_exposed()
    if warning:
        print(warning, file=sys.stderr, flush=True)
    print(f"chronocl viewer: {server.url}", flush=True)
    print("press Ctrl-C to stop", file=sys.stderr, flush=True)
    if open_browser:
        import webbrowser

        threading.Timer(0.5, webbrowser.open, args=(server.url,)).start()
    server.run()
