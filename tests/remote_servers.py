"""Real servers on loopback for the remote-store tests: a static HTTP server and moto's S3.

`StoreServer` serves a folder over HTTP/1.1 with Range requests, an injected latency per
request and a bandwidth limit shared by all connections (one link), counts the requests by
path, and can fail chosen keys: a status (`fail`) or a connection dropped halfway through the
body (`drop`, optionally only the first n times). `S3Server` is moto in server mode
(`ThreadedMotoServer`) on a free port, with `storage_options` for s3fs and a switch that makes
it check credentials. bench/remote.py serves its store with `StoreServer` too.
"""

from __future__ import annotations

import os
import re
import threading
import time
import urllib.request
from collections import Counter
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import unquote, urlsplit

_RANGE = re.compile(r"bytes=(\d*)-(\d*)$")


class StoreServer(ThreadingHTTPServer):
    """Serves `root` on 127.0.0.1 at a free port: `url(name)` is a file's or folder's URL."""

    daemon_threads = True
    block_on_close = False

    def __init__(self, root: Path, latency_s: float = 0.0, bytes_per_s: float = 0.0) -> None:
        super().__init__(("127.0.0.1", 0), _Handler)
        self.root = Path(root)
        self.latency_s, self.bytes_per_s = latency_s, bytes_per_s
        self.requests: Counter[str] = Counter()  # GETs by path below root
        self.fail: dict[str, int] = {}  # path -> HTTP status to answer with
        self.drop: dict[str, int] = {}  # path -> times left to drop the connection mid-body
        self.lock = threading.Lock()
        self.link_free = 0.0  # when the shared link is next free (time.monotonic)
        self._thread = threading.Thread(target=self.serve_forever, daemon=True)

    def __enter__(self) -> StoreServer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()
        self.server_close()
        self._thread.join(timeout=5)

    def url(self, name: str = "") -> str:
        host, port = self.server_address[:2]
        return f"http://{host}:{port}/{name}".rstrip("/")

    def chunk_requests(self) -> Counter[str]:
        """Requests for anything but metadata (zarr.json, .zarray, ...)."""
        return Counter(
            {
                p: n
                for p, n in self.requests.items()
                if not p.rsplit("/", 1)[-1].startswith(("zarr.json", "."))
            }
        )


class _Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    server: StoreServer

    def log_message(self, *args: object) -> None:  # quiet
        pass

    def do_HEAD(self) -> None:
        self._serve(body=False)

    def do_GET(self) -> None:
        self._serve(body=True)

    def _serve(self, body: bool) -> None:
        server = self.server
        rel = unquote(urlsplit(self.path).path).lstrip("/")
        if body:
            with server.lock:
                server.requests[rel] += 1
        if server.latency_s:
            time.sleep(server.latency_s)
        status = server.fail.get(rel)
        if status is not None:
            self._reply(status, b"injected failure\n")
            return
        file = (server.root / rel).resolve()
        if not file.is_relative_to(server.root.resolve()) or not file.is_file():
            self._reply(404, b"not found\n")
            return
        data = file.read_bytes()
        code, part = 200, data
        match = _RANGE.match(self.headers.get("Range", ""))
        if match and (match[1] or match[2]):
            n = len(data)
            if match[1]:
                start = int(match[1])
                end = min(int(match[2]) + 1, n) if match[2] else n
            else:  # a suffix: the last bytes
                start, end = max(0, n - int(match[2])), n
            if start >= n:
                self._reply(416, b"")
                return
            code, part = 206, data[start:end]
        self.send_response(code)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Content-Length", str(len(part)))
        self.send_header("Accept-Ranges", "bytes")
        if code == 206:
            self.send_header("Content-Range", f"bytes {start}-{end - 1}/{len(data)}")
        self.end_headers()
        if not body:
            return
        with server.lock:
            dropping = server.drop.get(rel, 0) > 0
            if dropping:
                server.drop[rel] -= 1
        if dropping:  # half the body, then the connection goes
            self.wfile.write(part[: len(part) // 2])
            self.wfile.flush()
            self.close_connection = True
            self.connection.shutdown(2)
            return
        self._send(part)

    def _send(self, part: bytes) -> None:
        """Write `part`, at most `bytes_per_s` over all connections together (one link)."""
        server = self.server
        rate = server.bytes_per_s
        if not rate:
            self.wfile.write(part)
            return
        piece = max(1, int(rate / 100))  # 10 ms of the link at a time
        for i in range(0, len(part), piece):
            chunk = part[i : i + piece]
            with server.lock:  # book the link for this piece after those booked before it
                start = max(time.monotonic(), server.link_free)
                server.link_free = start + len(chunk) / rate
                done = server.link_free
            time.sleep(max(0.0, done - time.monotonic()))
            self.wfile.write(chunk)

    def _reply(self, status: int, text: bytes) -> None:
        self.send_response(status)
        self.send_header("Content-Type", "text/plain")
        self.send_header("Content-Length", str(len(text)))
        self.end_headers()
        self.wfile.write(text)


class S3Server:
    """moto's S3 on 127.0.0.1 at a free port; `put(local, bucket, key)` uploads a store."""

    KEY, SECRET = "testing", "testing"

    def __init__(self) -> None:
        from moto.server import ThreadedMotoServer

        self.server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)

    def __enter__(self) -> S3Server:
        self.server.start()
        host, port = self.server.get_host_and_port()
        self.endpoint = f"http://{host}:{port}"
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.stop()

    def storage_options(self, key: str | None = None, secret: str | None = None) -> dict:
        return {
            "endpoint_url": self.endpoint,
            "key": key or self.KEY,
            "secret": secret or self.SECRET,
            "client_kwargs": {"region_name": "eu-west-1"},
        }

    def filesystem(self, **kwargs):
        import s3fs

        return s3fs.S3FileSystem(**self.storage_options(), skip_instance_cache=True, **kwargs)

    def put(self, local: Path, bucket: str, key: str, public: bool = False) -> str:
        """Upload the folder `local` to s3://bucket/key (the bucket made if new; `public`:
        readable by anyone, as a public data set's bucket); its URL."""
        acl = {"s3_additional_kwargs": {"ACL": "public-read"}} if public else {}
        fs = self.filesystem(**acl)
        if not fs.exists(bucket):
            fs.mkdir(bucket, **({"acl": "public-read"} if public else {}))
        for path in sorted(Path(local).rglob("*")):
            if path.is_file():
                fs.put_file(str(path), f"{bucket}/{key}/{path.relative_to(local).as_posix()}")
        return f"s3://{bucket}/{key}"

    def check_credentials(self, on: bool) -> None:
        """Make moto refuse requests whose keys it does not know (on) or accept any (off)."""
        count = "0" if on else "inf"
        req = urllib.request.Request(
            f"{self.endpoint}/moto-api/reset-auth",
            data=count.encode(),
            method="POST",
            headers={"Content-Type": "text/plain"},  # not a form: moto reads the raw body
        )
        with urllib.request.urlopen(req, timeout=10):
            pass


def env_without_aws() -> dict[str, str]:
    """The environment minus AWS settings that would steer s3fs away from the test server."""
    return {k: v for k, v in os.environ.items() if not k.startswith("AWS_")}
