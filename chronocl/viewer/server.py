"""The viewer's web server: the page, its assets, downloads and one WebSocket per client.

Starlette on uvicorn. Every request needs the server's random token: `?token=` in the URL
(the page then gets it as a cookie), the cookie, an `X-Chronocl-Token` header or
`Authorization: Bearer`; tokens are compared with `hmac.compare_digest`. The `Host` header
must name the address the server listens on (127.0.0.1, localhost or [::1] with its port, or
the host it was bound to; bound to 0.0.0.0 or ::, any IP address too, never another name), so a
DNS-rebinding page cannot reach it; a WebSocket whose `Origin` is not that host is refused.
At most `max_clients` sockets are served at once (each has a render thread); the next one is
told so and closed. The client names data sets only by index or name from the list the
server was started with. Errors in a message are answered and the socket stays up; nothing
sent to a client or printed carries a traceback.

    server = ViewerServer(["vortex.zarr"])   # 127.0.0.1, a free port
    print(server.url)                        # http://127.0.0.1:PORT/?token=...
    server.run()                             # or start() / stop() on a thread
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import hmac
import ipaddress
import json
import logging
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

from chronocl.core.errors import ChronoclError, InvalidParameterError, UnknownNameError
from chronocl.viewer.protocol import (
    MAX_MESSAGE_BYTES,
    MAX_VIEWS,
    ProtocolError,
    parse_message,
    request_id,
)
from chronocl.viewer.state import ClientWorker, Dataset, Downloads, internal_error

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
MAX_CLIENTS = 32
MAX_CLIENTS_LIMIT = 1000
WILDCARD = ("0.0.0.0", "::", "")
CLOSE_TRY_AGAIN = 1013  # WebSocket close code: try again later
HEAP_ALLOWANCE = 64 * 2**20  # growth since the last clean-up that starts another
HEAP_CHECK_S = 1.0

log = logging.getLogger("chronocl.viewer")


class _DenialNotAnError(logging.Filter):
    """uvicorn's websockets-sansio protocol logs "ASGI callable returned without completing
    handshake." at ERROR after every handshake answered with a denial response (the
    `websocket.http.response` extension), though the client got the response
    (Kludex/uvicorn#3138). This app answers every handshake (accept, close or denial), so
    that line only ever follows a refusal: it is dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "ASGI callable returned without completing handshake."


_DENIAL_FILTER = _DenialNotAnError()


def static_file(name: str) -> bytes:
    return (resources.files("chronocl.viewer") / "static" / name).read_bytes()


def open_datasets(stores: Sequence[str | os.PathLike]) -> list[Dataset]:
    """Open each store; names are the stores' stems, made unique with a suffix."""
    from chronocl.data.series import open_series

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


def check_options(
    *,
    host: object = "127.0.0.1",
    port: object = 0,
    engine: object = "opencl",
    device: object = None,
    memory: object = None,
    max_clients: object = MAX_CLIENTS,
    token: object = None,
) -> None:
    """Raise the ChronoclError naming the first bad server option (before anything starts)."""
    from chronocl.core.budget import parse_memory
    from chronocl.engine import ENGINES

    if not isinstance(host, str) or not host.strip() or any(c.isspace() for c in host):
        raise InvalidParameterError(f"host {host!r} is not an address; use e.g. 127.0.0.1")
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise InvalidParameterError(f"port {port!r} is outside 0..65535; use 0 for a free one")
    if engine not in ENGINES:
        raise UnknownNameError(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")
    if device is not None and not isinstance(device, str):
        raise InvalidParameterError(f"device {device!r} must be a string such as 0:1 or a name")
    if (
        isinstance(max_clients, bool)
        or not isinstance(max_clients, int)
        or not 1 <= max_clients <= MAX_CLIENTS_LIMIT
    ):
        raise InvalidParameterError(
            f"max_clients (--max-clients) {max_clients!r} must be an integer in "
            f"1..{MAX_CLIENTS_LIMIT}, e.g. {MAX_CLIENTS}"
        )
    if token is not None and (not isinstance(token, str) or len(token) < 8):
        raise InvalidParameterError("token must be a string of at least 8 characters")
    if memory is not None:
        parse_memory(memory)  # type: ignore[arg-type]
    if engine == "opencl" and device:
        from chronocl.engine.device import pick_device

        pick_device(device)  # raises EngineUnavailableError naming the devices there are


def host_names(host: str, port: int) -> frozenset[str]:
    """The Host header values (lower case) that name a server bound to host:port."""
    names = {"127.0.0.1", "localhost", "[::1]", f"[{host}]" if ":" in host else host}
    hosts = {f"{n}:{port}" for n in names}
    if port == 80:  # browsers leave the default port out
        hosts |= names
    return frozenset(h.lower() for h in hosts)


def is_ip_host(value: str, port: int) -> bool:
    """Whether a Host header is an IP address (not a name) with this port."""
    if value.startswith("["):  # [v6] or [v6]:port
        addr, _, rest = value[1:].partition("]")
        if rest and not rest.startswith(":"):
            return False
        given = rest[1:]
    elif value.count(":") <= 1:
        addr, _, given = value.partition(":")
    else:
        return False  # an IPv6 address needs brackets in a Host header
    if (given or "80") != str(port):
        return False
    try:
        ipaddress.ip_address(addr)
    except ValueError:
        return False
    return True


class HeapKeeper:
    """Keeps a long-running viewer's memory near what its clients use.

    Under 20 clients scrubbing and editing, a server leaves garbage that only a full
    collection frees (dask's task graphs of reads hold reference cycles; Python runs full
    collections rarely once many objects are long-lived), and glibc keeps what each render
    thread's arena freed. `check()` (once a second, off the event loop) collects and hands
    freed memory back (malloc_trim) once the process has grown by `allowance` over the least
    it used since the last clean-up; a clean-up stops every thread for tens of ms, so a quiet
    viewer seldom needs one. While the server runs, the objects it started with (modules,
    data sets) are frozen out of the collections (`gc.freeze`), which makes each collection
    several times cheaper under that load.
    """

    def __init__(self, allowance: int = HEAP_ALLOWANCE) -> None:
        from chronocl.core.budget import resident_bytes

        self.allowance = allowance
        self.floor = resident_bytes()
        self.cleanups = 0
        self.collect_s = 0.0  # collecting (every Python thread stopped), not waiting for it
        self.trim_s = 0.0  # in malloc_trim (threads go on)

    def freeze(self) -> None:
        gc.collect()
        gc.freeze()

    def unfreeze(self) -> None:
        gc.unfreeze()

    def check(self) -> None:
        import time

        from chronocl.core.budget import malloc_trim, resident_bytes

        now = resident_bytes()
        if now is None or self.floor is None:
            return
        if now <= self.floor + self.allowance:
            self.floor = min(self.floor, now)
            return
        started: list[float] = []

        def timer(phase: str, info: dict) -> None:
            if phase == "start":
                started.append(time.perf_counter())
            elif started:
                self.collect_s += time.perf_counter() - started.pop()

        gc.callbacks.append(timer)
        try:
            gc.collect()
        finally:
            gc.callbacks.remove(timer)
        t1 = time.perf_counter()
        if malloc_trim is not None:
            malloc_trim(0)
        self.floor = resident_bytes()
        self.cleanups += 1
        self.trim_s += time.perf_counter() - t1


class TokenGuard:
    """ASGI middleware: the Host and the token on every request, the Origin on sockets,
    safe headers. `host`/`port`: the address the server is bound to (port None: the port
    the request came in on)."""

    def __init__(self, app, token: str, host: str = "127.0.0.1", port: int | None = None) -> None:
        self.app = app
        self.token = token.encode()
        self.host = host
        self.port = port

    def host_ok(self, scope, headers: dict[str, str]) -> bool:
        value = headers.get("host", "").strip().lower()
        port = self.port if self.port is not None else (scope.get("server") or ("", 0))[1]
        if value in host_names(self.host, port):
            return True
        return self.host in WILDCARD and is_ip_host(value, port)

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
        if not self.host_ok(scope, headers):
            await self._refuse(
                scope, send, "the Host header does not name this server (DNS rebinding?)"
            )
            return
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
        body = (
            f"403 forbidden: {why}; open the URL with ?token=... that 'chronocl view' printed\n"
        ).encode()
        start = {
            "status": 403,
            "headers": [
                (b"content-type", b"text/plain; charset=utf-8"),
                (b"content-length", str(len(body)).encode()),
            ],
        }
        if scope["type"] == "websocket":
            if "websocket.http.response" in scope.get("extensions", {}):
                # The handshake is answered with 403 and the reason as its body.
                await send({"type": "websocket.http.response.start", **start})
                await send({"type": "websocket.http.response.body", "body": body})
            else:
                # Closing before accepting makes the server answer the handshake with 403.
                await send({"type": "websocket.close", "code": 1008, "reason": why})
            return
        await send({"type": "http.response.start", **start})
        await send({"type": "http.response.body", "body": body})


def make_app(
    datasets: list[Dataset],
    token: str,
    *,
    engine: str = "opencl",
    device: str | None = None,
    memory: str | int | None = None,
    downloads: Downloads | None = None,
    max_clients: int = MAX_CLIENTS,
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
            await serve_socket(websocket)
        except WebSocketDisconnect:
            pass
        except Exception as exc:  # one line in the log; the server goes on
            log.error("chronocl viewer: %s", internal_error(exc, "on a socket"))
            log.debug("chronocl viewer: socket failed", exc_info=True)
        finally:
            active -= 1

    async def serve_socket(websocket: WebSocket) -> None:
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
                except Exception as exc:  # a bug: answered and logged in one line, no traceback
                    log.error("chronocl viewer: %s", internal_error(exc, "on a message"))
                    log.debug("chronocl viewer: message failed", exc_info=True)
                    err = {"type": "error", "id": request_id(text)}
                    await deliver(
                        json.dumps(err | {"message": internal_error(exc, "on a message")})
                    )
        finally:
            gone.set()
            worker.close()

    async def keep_heap() -> None:
        while True:
            await asyncio.sleep(HEAP_CHECK_S)
            await asyncio.to_thread(heap.check)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        heap.freeze()
        keeper = asyncio.create_task(keep_heap())
        try:
            yield
        finally:
            keeper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await keeper
            heap.unfreeze()
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
    guard = TokenGuard(app, token, host=host, port=port)
    guard.heap = heap  # type: ignore[attr-defined]  # its counters, for benchmarks
    return guard


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
    """`chronocl view`: serve the given stores on host:port (port 0: a free one), at most
    `max_clients` sockets at once. Every option is checked (ChronoclError) before the stores
    are opened or the port bound."""

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
        max_clients: int = MAX_CLIENTS,
    ) -> None:
        import uvicorn

        check_options(
            host=host,
            port=port,
            engine=engine,
            device=device,
            memory=memory,
            max_clients=max_clients,
            token=token,
        )
        self.datasets = datasets if datasets is not None else open_datasets(stores or [])
        self.token = token or secrets.token_urlsafe(24)
        self.host = host
        self.max_clients = max_clients
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
        self.app = app = make_app(
            self.datasets,
            self.token,
            engine=engine,
            device=device,
            memory=memory,
            downloads=self.downloads,
            max_clients=max_clients,
            host=host,
            port=self.port,
        )
        config = uvicorn.Config(
            app,
            log_level="warning",
            ws_max_size=4 * MAX_MESSAGE_BYTES,
            ws_per_message_deflate=False,
            lifespan="on",
        )
        logging.getLogger("uvicorn.error").addFilter(_DENIAL_FILTER)  # idempotent
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
    max_clients: int = MAX_CLIENTS,
) -> None:
    """Run the viewer: print the URL (with its token), open the browser, serve until Ctrl-C.

    Every argument is checked first; a bad one raises the ChronoclError naming it and the fix.
    """
    if not isinstance(open_browser, bool):
        raise InvalidParameterError(f"open_browser {open_browser!r} must be true or false")
    server = ViewerServer(
        stores,
        host=host,
        port=port,
        engine=engine,
        device=device,
        memory=memory,
        max_clients=max_clients,
    )
    warning = server.warn_if_exposed()
    if warning:
        print(warning, file=sys.stderr, flush=True)
    print(f"chronocl viewer: {server.url}", flush=True)
    print("press Ctrl-C to stop", file=sys.stderr, flush=True)
    if open_browser:
        import webbrowser

        threading.Timer(0.5, webbrowser.open, args=(server.url,)).start()
    server.run()
