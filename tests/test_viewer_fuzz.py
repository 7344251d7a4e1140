"""Abuse of a real viewer server (`chronocl view` in a subprocess on 127.0.0.1): malformed,
non-object, oversized and deeply nested messages, out-of-range and wrong-typed fields
(hypothesis), wrong tokens, foreign Origin and Host headers, more sockets than the cap.

Each case must be answered with an error (or the connection refused), another well-behaved
client must still get frames, nothing sent back may carry a traceback or a source path, and
the server's stderr must never show one."""

from __future__ import annotations

import http.client
import json
import math
import socket
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

pytest.importorskip("starlette")
pytest.importorskip("websockets")

from hypothesis import given, settings
from hypothesis import strategies as st
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.sync.client import connect

import chronocl
from chronocl.core.errors import ChronoclError
from chronocl.viewer.guard import host_names, is_ip_host
from chronocl.viewer.protocol import FLOAT32_MAX, LIMITS, MESSAGES
from chronocl.viewer.server import ViewerServer, serve

from .strategies import examples
from .viewer_helpers import Client, CliServer, make_stores

CAP = 4  # --max-clients of the server under test
SOURCE = str(Path(chronocl.__file__).resolve().parents[1])  # no path of ours goes to a client
POINTS = [[0.0, 1, 1, 1, 0.0], [1.0, 1, 1, 1, 1.0]]


def assert_clean(text: str) -> None:
    """What a client got: nothing like a traceback or a path of the server's files."""
    assert_no_traceback(text)
    assert SOURCE not in text, text


def assert_no_traceback(text: str) -> None:
    """What the server printed: no traceback, no unexpected error."""
    assert "Traceback" not in text, text
    assert 'File "/' not in text, text
    assert "internal error" not in text, text
    assert "Exception in ASGI application" not in text, text


@pytest.fixture(scope="module")
def stores(tmp_path_factory):
    return make_stores(tmp_path_factory.mktemp("viewer-fuzz"))


@pytest.fixture(scope="module")
def server(stores, tmp_path_factory):
    log = tmp_path_factory.mktemp("viewer-fuzz-log") / "stderr.txt"
    srv = CliServer(stores, log, "--max-clients", str(CAP))
    yield srv
    srv.stop()
    assert_no_traceback(srv.stderr())


@pytest.fixture(scope="module")
def good(server):
    """The well-behaved client: it must keep getting frames whatever the others do."""
    c = Client(server)
    c.open(0, size=(64, 64))
    yield c
    c.close()


@pytest.fixture(scope="module")
def fuzzer(server):
    c = Client(server)
    c.open(1, size=(64, 64))
    yield c
    c.close()


@pytest.fixture(autouse=True)
def still_serving(request):
    """After each test that uses the server: it is alive, printed no traceback, and the
    well-behaved client still gets a frame."""
    if "server" not in request.fixturenames:
        yield
        return
    server = request.getfixturevalue("server")
    good = request.getfixturevalue("good")
    start = len(server.stderr())
    yield
    rid = good.send({"type": "update", "camera": {"azimuth": float(time.monotonic() % 360)}})
    _, header, images = good.frame_for(rid, timeout=60)
    assert header["id"] >= rid and images[0][:2] == b"\xff\xd8"
    assert server.alive()
    assert_no_traceback(server.stderr(start))


def reply_to(client: Client, rid: int, timeout: float = 60.0):
    """The answer to request `rid`: ('error', msg), ('frame', header) or (type, msg); every
    text message on the way is checked for tracebacks."""
    deadline = time.monotonic() + timeout
    while True:
        got = client.recv(max(0.1, deadline - time.monotonic()))
        if got[0] != "frame":
            assert_clean(json.dumps(got[1]))
        if got[0] == "frame":
            if (got[1]["id"] or 0) >= rid:
                return got[0], got[1]
        elif got[1].get("id") == rid:
            return got


def error_for(client: Client, text: str | bytes, rid: int | None = None) -> str:
    """Send raw `text`; the error reply's message (the next error, or the one for `rid`)."""
    client.send_raw(text)
    while True:
        got = client.recv(60)
        if got[0] == "error" and (rid is None or got[1]["id"] == rid):
            assert_clean(got[1]["message"])
            return got[1]["message"]


def raw_upgrade(server) -> socket.socket:
    """A WebSocket handshake on a bare socket (to drop it without a close frame)."""
    s = socket.create_connection(("127.0.0.1", server.port), timeout=30)
    s.sendall(
        (
            f"GET /ws?token={server.token} HTTP/1.1\r\nHost: 127.0.0.1:{server.port}\r\n"
            "Upgrade: websocket\r\nConnection: Upgrade\r\n"
            "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    assert s.recv(4096).startswith(b"HTTP/1.1 101")
    return s


def get(url: str, headers: dict | None = None) -> tuple[int, bytes]:
    req = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


# --------------------------------------------------------------------------- messages

MALFORMED = [
    "",
    "{",
    "}",
    '{"type": "update",',
    "{'type': 'update'}",
    "nul",
    "NaN",
    "-Infinity",
    '{"type": "update", "threshold": NaN}',
    '{"type": "update", "threshold": Infinity}',
    '{"type": "update"} trailing',
    '{"type": "update", "threshold": 0.5,}',
    '{"type": "update", "threshold": ' + "9" * 5000 + "}",
    '"\\ud800"',
    "\x00\x01\x02",
]
NOT_OBJECTS = ["[]", "[1, 2]", "3", "-0.5", '"update"', "null", "true", "false"]


@pytest.mark.parametrize("text", MALFORMED + NOT_OBJECTS)
def test_malformed_and_non_object_json_get_an_error(server, fuzzer, text):
    message = error_for(fuzzer, text)
    assert "JSON" in message or "message" in message


def test_deeply_nested_messages_are_refused_before_decoding(server, fuzzer):
    n = 20_000  # 40 KB, under the size limit: json.loads alone would raise RecursionError
    for text in (
        "[" * n + "]" * n,
        '{"type": "update", "camera": ' + "[" * n + "]" * n + "}",
        '{"a":' * 5000 + "1" + "}" * 5000,
        '{"type": "update", "id": 7, "x": '
        + "[" * (LIMITS.depth + 1)
        + "]" * (LIMITS.depth + 1)
        + "}",
        "[" * n,  # unbalanced
    ):
        assert "nests" in error_for(fuzzer, text)
    # Brackets inside strings are not nesting.
    deep_string = '{"type": "update", "id": 9, "x": "' + "[" * n + '"}'
    assert "unknown field 'x'" in error_for(fuzzer, deep_string, rid=9)


@pytest.mark.parametrize("binary", [False, True])
def test_messages_over_10_mb_close_that_socket_only(server, binary):
    abuser = Client(server, max_size=None)
    data = b"\x00" * (10 * 2**20) if binary else '{"type": "update", "x": "' + "y" * 10 * 2**20
    try:
        abuser.send_raw(data)
        while True:  # an error reply, or the socket closed (1009: too big)
            got = abuser.recv(30)
            if got[0] == "error":
                assert_clean(got[1]["message"])
                break
    except TimeoutError:  # an OSError too: a server that neither answers nor closes fails
        pytest.fail("the server neither answered the message over 10 MB nor closed the socket")
    except (ConnectionClosed, OSError):  # closed (1009), or reset while the message was sent
        pass
    finally:
        abuser.close()


def test_between_the_message_limit_and_the_frame_limit_is_answered(server, fuzzer):
    text = json.dumps({"type": "update", "pad": "x" * 100_000})
    assert "over the limit" in error_for(fuzzer, text)
    assert "binary" in error_for(fuzzer, b"\x00" * 1000)


@pytest.mark.parametrize(
    "msg, expected",
    [
        ({"type": "update", "id": -1}, "update.id"),
        ({"type": "update", "id": 2**60}, "update.id"),
        ({"type": "update", "id": "7"}, "update.id"),
        ({"type": "update", "id": True}, "update.id"),
        ({"id": 3}, "unknown message type"),
        ({"type": ["update"]}, "unknown message type"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [-1e300, 1e300]}}, "lie"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [-3e38, 3e38]}}, "span"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [2.0, 1.0]}}, "lo < hi"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [1.0, 1.0]}}, "lo < hi"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [0, 1e-300]}}, "span"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [0, "1"]}}, "number"),
        ({"type": "update", "data_tf": {"points": POINTS, "value_range": [0]}}, "entries"),
        ({"type": "update", "camera": {"zoom": 10**400}}, "camera.zoom"),
        ({"type": "update", "window": {"t0": 0, "t1": 10**30}}, "window.t1"),
        ({"type": "update", "size": [64.0, 64]}, "integer"),
        ({"type": "update", "views": [{"mode": "max"}] * 5}, "views"),
        ({"type": "update", "data_tf": {"points": [POINTS[0]] * 65}}, "points"),
        ({"type": "histogram", "range": [0.5, 0.5]}, "lo < hi"),
        ({"type": "probe", "x": -0.1, "y": 0.5}, "probe.x"),
        ({"type": "open", "dataset": "/etc/passwd"}, "unknown data set"),
        ({"type": "open", "dataset": 10**6}, "open.dataset"),
        ({"type": "save", "what": "chronovolume", "view": 3}, "not shown"),
    ],
)
def test_wrong_fields_get_an_error_naming_them(server, fuzzer, msg, expected):
    rid = fuzzer.next_id
    fuzzer.next_id += 1
    text = json.dumps(msg if "id" in msg else {**msg, "id": rid})
    message = error_for(fuzzer, text, rid=rid if "id" not in msg else None)
    assert expected in message, (msg, message)


JSON = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | st.floats() | st.text(max_size=10),
    lambda inner: (
        st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)
FIELDS = {kind: sorted(set(obj.fields) - {"type", "id"}) for kind, obj in MESSAGES.items()}


@st.composite
def messages(draw) -> dict:
    kind = draw(st.sampled_from([*MESSAGES, "bogus"]))
    keys = st.sampled_from([*FIELDS.get(kind, []), "extra"])
    return {"type": kind, **draw(st.dictionaries(keys, JSON, max_size=3))}


def non_finite(value: object) -> bool:
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, dict):
        return any(non_finite(v) for v in value.values())
    if isinstance(value, list):
        return any(non_finite(v) for v in value)
    return False


@settings(max_examples=examples(40))
@given(msg=messages())
def test_random_messages_are_answered_never_crash(server, fuzzer, msg):
    rid = fuzzer.send(msg)  # NaN and Infinity go out as such: they must be refused
    kind, reply = reply_to(fuzzer, rid)
    if non_finite(msg):
        assert kind == "error" and "not allowed" in reply["message"], (msg, reply)


NUMBERS = st.one_of(
    st.floats(),
    st.integers(-(2**80), 2**80),
    st.sampled_from([1e300, -1e300, 3.5e38, -3.5e38, FLOAT32_MAX, 1e-320, 2**53 + 1, -0.0]),
)
NUMERIC_FIELDS = {
    "camera.azimuth": lambda x: {"type": "update", "camera": {"azimuth": x}},
    "camera.zoom": lambda x: {"type": "update", "camera": {"zoom": x}},
    "threshold": lambda x: {"type": "update", "threshold": x},
    "time_tf.width": lambda x: {"type": "update", "time_tf": {"width": x}},
    "enhance.k1": lambda x: {"type": "update", "enhance": {"kind": "edge", "k1": x}},
    "clip.offset": lambda x: {"type": "update", "clip": {"normal": [0, 0, 1], "offset": x}},
    "value_range.lo": lambda x: {
        "type": "update",
        "data_tf": {"points": POINTS, "value_range": [x, 1.0]},
    },
    "value_range.hi": lambda x: {
        "type": "update",
        "data_tf": {"points": POINTS, "value_range": [0.0, x]},
    },
    "value_range.both": lambda x: {
        "type": "update",
        "data_tf": {"points": POINTS, "value_range": [-x, x]},
    },
    "window.t1": lambda x: {"type": "update", "window": {"t0": 0, "t1": x}},
    "size": lambda x: {"type": "update", "size": [x, 64]},
    "histogram.hi": lambda x: {"type": "histogram", "range": [0.0, x]},
    "probe.x": lambda x: {"type": "probe", "x": x, "y": 0.5},
}


def fits_float32(*values: float) -> bool:
    return all(math.isfinite(v) and abs(v) <= FLOAT32_MAX for v in values)


@settings(max_examples=examples(40))
@given(field=st.sampled_from(sorted(NUMERIC_FIELDS)), x=NUMBERS)
def test_numbers_out_of_range_are_refused_and_accepted_ones_fit(server, fuzzer, field, x):
    msg = NUMERIC_FIELDS[field](x)
    rid = fuzzer.send(msg)
    kind, _ = reply_to(fuzzer, rid)
    if kind != "error":  # accepted: then it was a finite float32 value, and ranges ordered
        assert fits_float32(float(x)), (field, x, kind)
        if field.startswith("value_range"):
            lo, hi = msg["data_tf"]["value_range"]
            assert lo < hi and fits_float32(hi - lo)


# --------------------------------------------------------------------------- access


def test_wrong_or_missing_tokens_are_refused(server):
    base = f"ws://127.0.0.1:{server.port}/ws"
    for url in (base, f"{base}?token=", f"{base}?token=nope", f"{base}?token={server.token}x"):
        with pytest.raises(InvalidStatus) as exc:
            connect(url)
        assert exc.value.response.status_code == 403
        assert b"token" in exc.value.response.body
    assert get(f"{server.base}/?token=wrong")[0] == 403
    assert get(f"{server.base}/", {"Authorization": "Bearer wrong"})[0] == 403
    assert get(f"{server.base}/", {"Cookie": f"chronocl_token_{server.port}=wrong"})[0] == 403


def test_foreign_origin_is_refused(server):
    url = f"ws://127.0.0.1:{server.port}/ws?token={server.token}"
    for origin in ("http://evil.example", f"http://evil.example:{server.port}", "null"):
        with pytest.raises(InvalidStatus) as exc:
            connect(url, origin=origin)
        assert exc.value.response.status_code == 403
    ok = Client(server, origin=f"http://127.0.0.1:{server.port}")
    ok.close()


def ws_as(server, host: str):
    """A WebSocket to the server with the token, sent with `host` as its one Host header and a
    matching Origin, as a browser sends it after DNS rebinding: the URL names `host`, the socket
    goes to 127.0.0.1. (A Host in additional_headers would be a second one, beside the URL's.)"""
    url = f"ws://{host}/ws?token={server.token}"
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=30)
    return connect(url, sock=sock, origin=f"http://{host}")


def test_foreign_host_is_refused_even_with_the_token_and_a_matching_origin(server):
    """DNS rebinding: evil.example resolves to 127.0.0.1; the page's Host and Origin agree."""
    p = server.port
    for host in (f"evil.example:{p}", "evil.example", f"127.0.0.1:{p + 1}", f"10.0.0.1:{p}"):
        with pytest.raises(InvalidStatus) as exc:
            ws_as(server, host)
        assert exc.value.response.status_code == 403
        assert b"Host" in exc.value.response.body
        status, body = get(server.url, {"Host": host})
        assert status == 403 and b"Host" in body
    # The names of the loopback address are this server.
    for host in (f"localhost:{p}", f"[::1]:{p}", f"127.0.0.1:{p}"):
        assert get(server.url, {"Host": host})[0] == 200
        with ws_as(server, host) as ws:
            assert json.loads(ws.recv(timeout=60))["type"] == "info"
    # Two Host headers (the URL's, then another), either one ours: no browser sends them. h11
    # refuses them itself (RFC 9112: 400) before any of our code runs; httptools passes both
    # on, and the guard refuses them (it once read the last one alone).
    foreign, ours = f"evil.example:{p}", f"127.0.0.1:{p}"
    for first, second in ((ours, foreign), (foreign, ours)):
        url = f"ws://{first}/ws?token={server.token}"
        sock = socket.create_connection(("127.0.0.1", p), timeout=30)
        with pytest.raises(InvalidStatus) as exc:
            connect(url, sock=sock, additional_headers={"Host": second}, origin=f"http://{second}")
        response = exc.value.response
        if response.status_code == 400:  # uvicorn's own refusal (h11), before the guard
            assert bytes(response.body) == b"Invalid HTTP request received."
        else:  # the guard's
            assert response.status_code == 403 and b"Host" in response.body
    # No Host at all.
    conn = http.client.HTTPConnection("127.0.0.1", p, timeout=30)
    conn.putrequest("GET", f"/?token={server.token}", skip_host=True)
    conn.endheaders()
    response = conn.getresponse()
    assert response.status in (400, 403)
    conn.close()


def test_host_names_and_ip_hosts():
    assert host_names("127.0.0.1", 8765) == {"127.0.0.1:8765", "localhost:8765", "[::1]:8765"}
    assert "[::1]:8765" in host_names("::1", 8765)
    assert "viz.example.org:80" in host_names("viz.example.org", 80)
    assert "viz.example.org" in host_names("viz.example.org", 80)
    assert is_ip_host("192.168.1.5:8765", 8765) and is_ip_host("[fe80::1]:8765", 8765)
    for value in ("evil.example:8765", "192.168.1.5:8766", "192.168.1.5", "fe80::1:8765", ""):
        assert not is_ip_host(value, 8765)


# --------------------------------------------------------------------------- the cap


def test_connections_over_the_cap_get_an_error_and_are_closed(server, good, fuzzer):
    extra = [Client(server) for _ in range(CAP - 2)]  # good and fuzzer hold two
    with connect(f"ws://127.0.0.1:{server.port}/ws?token={server.token}") as over:
        reply = json.loads(over.recv(30))
        assert reply["type"] == "error" and "--max-clients" in reply["message"]
        assert_clean(reply["message"])
        with pytest.raises(ConnectionClosed) as exc:
            over.recv(30)
    assert exc.value.rcvd is not None and exc.value.rcvd.code == 1013
    # The ones under the cap are served.
    for c in extra:
        c.open(0, size=(64, 64))
    for c in extra:
        c.close()
    # Closed sockets, cleanly or not, give their places back.
    for k in range(3 * CAP):
        if k % 2:
            raw_upgrade(server).close()  # dropped without a close frame
        else:
            with connect(f"ws://127.0.0.1:{server.port}/ws?token={server.token}"):
                pass  # closed cleanly on leaving
    deadline = time.monotonic() + 30
    while True:
        clients = []
        try:
            clients = [Client(server) for _ in range(CAP - 2)]
            assert all(c.info["type"] == "info" for c in clients)
            break
        except AssertionError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
        finally:
            for c in clients:
                c.close()


# --------------------------------------------------------------------------- options


@pytest.mark.parametrize(
    "kwargs, expected",
    [
        ({"memory": "lots"}, "not a size"),
        ({"memory": -5}, "positive"),
        ({"port": 70000}, "0..65535"),
        ({"port": -1}, "0..65535"),
        ({"port": "80"}, "0..65535"),
        ({"max_clients": 0}, "--max-clients"),
        ({"max_clients": True}, "--max-clients"),
        ({"max_clients": 10**6}, "--max-clients"),
        ({"max_clients": 2.5}, "--max-clients"),
        ({"engine": "cuda"}, "unknown engine"),
        ({"host": ""}, "not an address"),
        ({"host": "a b"}, "not an address"),
        ({"host": 5}, "not an address"),
        ({"device": 3}, "device"),
        ({"open_browser": "yes"}, "open_browser"),
        ({"host": "203.0.113.7"}, "cannot listen"),
    ],
)
def test_serve_checks_every_argument_before_starting(stores, monkeypatch, kwargs, expected):
    monkeypatch.setattr(ViewerServer, "run", lambda self: pytest.fail("the server started"))
    kwargs = {"open_browser": False, **kwargs}
    with pytest.raises(ChronoclError) as exc:
        serve(stores, **kwargs)
    assert isinstance(exc.value, ValueError)
    assert expected in str(exc.value) and "\n" not in str(exc.value)
    # Options are checked before the stores are opened.
    if "host" not in kwargs or kwargs["host"] != "203.0.113.7":
        with pytest.raises(ChronoclError, match=expected.replace(".", r"\.")):
            serve([stores[0].parent / "missing.zarr"], **kwargs)


def test_cli_refuses_a_bad_memory_budget_before_serving(stores):
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "chronocl", "view", str(stores[0]), "--no-browser"]
    for args, expected in ((["--memory", "lots"], "not a size"), (["--max-clients", "0"], "1..")):
        done = subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done
        assert done.stdout == "" and expected in done.stderr and done.stderr.count("\n") == 1
