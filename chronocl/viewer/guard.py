"""The viewer's front door: an ASGI middleware that checks the Host and the token on every
request and the Origin on sockets, and adds safe headers.

Every request needs the server's random token: `?token=` in the URL (the page then gets it as
a cookie), the cookie, an `X-Chronocl-Token` header or `Authorization: Bearer`; tokens are
compared with `hmac.compare_digest`. The `Host` header must name the address the server
listens on (127.0.0.1, localhost or [::1] with its port, or the host it was bound to; bound to
0.0.0.0 or ::, any IP address too, never another name), so a DNS-rebinding page cannot reach
it; a WebSocket whose `Origin` is not that host is refused.
"""

from __future__ import annotations

import contextlib
import hmac
import ipaddress
from http.cookies import SimpleCookie
from urllib.parse import parse_qs, urlsplit

CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
    "connect-src 'self'; form-action 'none'; frame-ancestors 'none'; base-uri 'none'"
)
WILDCARD = ("0.0.0.0", "::", "")


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
        names = [k.lower() for k, _ in scope["headers"]]
        if names.count(b"host") > 1 or names.count(b"origin") > 1:  # which one is meant?
            await self._refuse(scope, send, "two Host or Origin headers (one of each is allowed)")
            return
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
