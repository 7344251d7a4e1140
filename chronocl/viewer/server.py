"""The viewer's web server: `ViewerServer` binds host:port and serves the application
(`app.make_app`) with uvicorn; `serve` is `chronocl view`.

Starlette on uvicorn. Every request needs the server's random token and a Host header naming
this server (`guard`). At most `max_clients` sockets are served at once (each has a render
thread); the next one is told so and closed. The client names data sets only by index or
name from the list the server was started with. Every option is checked before anything
starts; a bad one raises the ChronoclError naming it.

    server = ViewerServer(["vortex.zarr"])   # 127.0.0.1, a free port
    print(server.url)                        # http://127.0.0.1:PORT/?token=...
    server.run()                             # or start() / stop() on a thread

The token is random unless given, or set in $CHRONOCL_VIEWER_TOKEN: a server restarted on the
same port with the same token is one an open page reconnects to by itself.
"""

from __future__ import annotations

import logging
import os
import re
import secrets
import socket
import sys
import threading
from collections.abc import Sequence

from chronocl.core import env
from chronocl.core.budget import human, interactive_memory, parse_memory
from chronocl.core.errors import InvalidParameterError
from chronocl.viewer.app import make_app
from chronocl.viewer.datasets import Dataset, open_datasets
from chronocl.viewer.protocol import LIMITS
from chronocl.viewer.saving import Downloads

LOOPBACK = ("127.0.0.1", "localhost", "::1")
TOKEN_ENV = "CHRONOCL_VIEWER_TOKEN"


class _DenialNotAnError(logging.Filter):
    """uvicorn's websockets-sansio protocol logs "ASGI callable returned without completing
    handshake." at ERROR after every handshake answered with a denial response (the
    `websocket.http.response` extension), though the client got the response
    (Kludex/uvicorn#3138). This app answers every handshake (accept, close or denial), so
    that line only ever follows a refusal: it is dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() != "ASGI callable returned without completing handshake."


_DENIAL_FILTER = _DenialNotAnError()


def check_options(
    *,
    host: object = "127.0.0.1",
    port: object = 0,
    engine: object = "opencl",
    device: object = None,
    memory: object = None,
    max_clients: object = LIMITS.clients,
    token: object = None,
) -> None:
    """Raise the ChronoclError naming the first bad server option (before anything starts)."""
    from chronocl.engine import check_engine

    if not isinstance(host, str) or not host.strip() or any(c.isspace() for c in host):
        raise InvalidParameterError(f"host {host!r} is not an address; use e.g. 127.0.0.1")
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise InvalidParameterError(f"port {port!r} is outside 0..65535; use 0 for a free one")
    check_engine(engine)
    if device is not None and not isinstance(device, str):
        raise InvalidParameterError(f"device {device!r} must be a string such as 0:1 or a name")
    if (
        isinstance(max_clients, bool)
        or not isinstance(max_clients, int)
        or not 1 <= max_clients <= LIMITS.clients_most
    ):
        raise InvalidParameterError(
            f"max_clients (--max-clients) {max_clients!r} must be an integer in "
            f"1..{LIMITS.clients_most}, e.g. {LIMITS.clients}"
        )
    if token is not None and (not isinstance(token, str) or len(token) < 8):
        raise InvalidParameterError("token must be a string of at least 8 characters")
    if memory is not None:
        parse_memory(memory)  # type: ignore[arg-type]
    if engine == "opencl" and device:
        from chronocl.engine.device import pick_device

        pick_device(device)  # raises EngineUnavailableError naming the devices there are


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
        max_clients: int = LIMITS.clients,
        storage_options: dict | None = None,
    ) -> None:
        import uvicorn

        if token is None and env.get(TOKEN_ENV):
            token = env.get(TOKEN_ENV)
            if not re.fullmatch(r"[A-Za-z0-9_-]{8,}", token):
                raise InvalidParameterError(
                    f"${TOKEN_ENV} must be at least 8 letters, digits, '_' or '-' "
                    "(it goes into the URL); unset it for a random token"
                )
        check_options(
            host=host,
            port=port,
            engine=engine,
            device=device,
            memory=memory,
            max_clients=max_clients,
            token=token,
        )
        if datasets is None:
            datasets = open_datasets(stores or [], storage_options)
        self.datasets = datasets
        # One limit for the process, taken from the memory free when the server starts.
        memory = interactive_memory() if memory is None else memory
        self.memory = parse_memory(memory)
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
            ws_max_size=4 * LIMITS.message_bytes,
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
    max_clients: int = LIMITS.clients,
    storage_options: dict | None = None,
) -> None:
    """Run the viewer: print the URL (with its token), open the browser, serve until Ctrl-C.
    `stores` are paths or http(s):// / s3:// URLs (read with `storage_options`).

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
        storage_options=storage_options,
    )
    warning = server.warn_if_exposed()
    if warning:
        print(warning, file=sys.stderr, flush=True)
    print(f"chronocl viewer: {server.url}", flush=True)
    print(
        f"memory limit {human(server.memory)}"
        + (" (half the memory free; --memory sets it)" if memory is None else ""),
        file=sys.stderr,
        flush=True,
    )
    print("press Ctrl-C to stop", file=sys.stderr, flush=True)
    if open_browser:
        import webbrowser

        threading.Timer(0.5, webbrowser.open, args=(server.url,)).start()
    server.run()
