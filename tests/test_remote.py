"""Series read where they live: over HTTP and S3 from real servers on loopback (no mocks).

The HTTP server is `tests.remote_servers.StoreServer` (Range requests, latency, bandwidth,
injected failures); S3 is moto in server mode. A remote store reads and integrates exactly as
its local copy does; every failure is one clear error (CLI: one line, exit 2, nothing written),
never zeros.
"""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import chronocl
from chronocl.cli.options import series_store
from chronocl.core.errors import (
    InputNotFoundError,
    InvalidParameterError,
    RemoteAccessError,
    RemoteStoreError,
    StoreCorruptError,
)
from chronocl.data.level_writer import add_levels
from chronocl.data.remote import parse_storage_options
from chronocl.data.series import write_series

from .bad_input import partials
from .remote_servers import S3Server, StoreServer, env_without_aws

pytest.importorskip("s3fs")
pytest.importorskip("moto.server")

SHAPE = (5, 16, 16, 80)  # the longest axis above 64: the store has one coarse level
CHUNK = "s.zarr/data/c/{}/0/0/0"


@pytest.fixture(autouse=True)
def quick_retries(monkeypatch):
    monkeypatch.setenv("CHRONOCL_REMOTE_RETRIES", "2")
    monkeypatch.setenv("CHRONOCL_REMOTE_BACKOFF_S", "0.01")


@pytest.fixture(scope="module")
def served(tmp_path_factory) -> Path:
    """A folder holding s.zarr, a small chronocl store with coarse levels."""
    root = tmp_path_factory.mktemp("served")
    data = np.random.default_rng(3).random(SHAPE, dtype=np.float32)
    write_series(
        root / "s.zarr",
        list(data),
        n_steps=SHAPE[0],
        volume_shape=SHAPE[1:],
        dtype=np.float32,
        times=[0.5 * t for t in range(SHAPE[0])],
    )
    add_levels(root / "s.zarr")
    return root


@pytest.fixture
def http(served):
    with StoreServer(served) as server:
        yield server


@pytest.fixture(scope="module")
def s3(served):
    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    with S3Server() as server:
        server.url = server.put(served / "s.zarr", "chronocl-test", "runs/s.zarr")
        server.public_url = server.put(served / "s.zarr", "chronocl-public", "s.zarr", True)
        yield server


def same_series(remote, local) -> None:
    assert remote.shape == local.shape and remote.stats == local.stats
    assert remote.times == local.times and remote.spacing == local.spacing
    np.testing.assert_array_equal(remote.read(range(SHAPE[0])), local.read(range(SHAPE[0])))
    assert remote.n_levels == local.n_levels == 2
    np.testing.assert_array_equal(remote.level(1).read([1, 3]), local.level(1).read([1, 3]))
    for mode in ("max", "alpha"):
        a = chronocl.integrate(remote, "0:5", mode=mode, engine="numpy")
        b = chronocl.integrate(local, "0:5", mode=mode, engine="numpy")
        np.testing.assert_array_equal(a.rgba, b.rgba)
        assert a.metadata["value_range"] == b.metadata["value_range"]


def test_http_store_reads_and_integrates_as_local(served, http):
    remote = chronocl.open(http.url("s.zarr"))
    assert remote.path is None and remote.describe()["path"] == http.url("s.zarr")
    same_series(remote, chronocl.open(served / "s.zarr"))
    assert http.requests["s.zarr/data/zarr.json"] >= 1


def test_http_with_latency_and_bandwidth_limit(served):
    with StoreServer(served, latency_s=0.01, bytes_per_s=20e6) as slow:
        remote = chronocl.open(slow.url("s.zarr"))
        np.testing.assert_array_equal(remote.read([4]), chronocl.open(served / "s.zarr").read([4]))


def test_s3_store_reads_and_integrates_as_local(served, s3):
    remote = chronocl.open(s3.url, storage_options=s3.storage_options())
    same_series(remote, chronocl.open(served / "s.zarr"))
    # A public bucket: unsigned requests (--anon).
    public = {"anon": True, "endpoint_url": s3.endpoint}
    np.testing.assert_array_equal(
        chronocl.open(s3.public_url, storage_options=public).read([0]), remote.read([0])
    )
    with pytest.raises(RemoteAccessError, match="refused"):  # a private one refuses them
        chronocl.open(s3.url, storage_options=public)


def test_missing_chunk_is_corruption_naming_the_key(served, http, s3):
    http.fail[CHUNK.format(2)] = 404
    with pytest.raises(StoreCorruptError, match=r"chunk data/c/2/0/0/0 \(step 2\) is missing"):
        chronocl.open(http.url("s.zarr")).read([2])
    url = s3.put(served / "s.zarr", "chronocl-test", "damaged/s.zarr")
    s3.filesystem().rm(f"{url[5:]}/data/c/3/0/0/0")
    remote = chronocl.open(url, storage_options=s3.storage_options())
    np.testing.assert_array_equal(remote.read([2]), chronocl.open(served / "s.zarr").read([2]))
    with pytest.raises(StoreCorruptError, match=r"s3://.*chunk data/c/3/0/0/0 \(step 3\)"):
        remote.read([3])


def test_truncated_chunk_is_corruption(served, tmp_path):
    shutil.copytree(served / "s.zarr", tmp_path / "s.zarr")
    chunk = tmp_path / CHUNK.format(1)
    chunk.write_bytes(chunk.read_bytes()[:100])
    with StoreServer(tmp_path) as server:
        with pytest.raises(StoreCorruptError, match=r"chunk data/c/1/0/0/0 .* cannot be decoded"):
            chronocl.open(server.url("s.zarr")).read([1])


def test_network_failures_are_retried_then_one_error(served, http):
    local = chronocl.open(served / "s.zarr")
    remote = chronocl.open(http.url("s.zarr"))
    http.drop[CHUNK.format(1)] = 2  # dropped twice mid-body, then served: two retries suffice
    np.testing.assert_array_equal(remote.read([1]), local.read([1]))
    assert http.requests[CHUNK.format(1)] == 3
    http.drop[CHUNK.format(2)] = 99
    with pytest.raises(RemoteStoreError, match=r"data/c/2/0/0/0 failed after 3 tries: the conn"):
        remote.read([2])
    http.fail[CHUNK.format(3)] = 503
    with pytest.raises(ConnectionError, match=r"data/c/3/0/0/0 failed after 3 tries: HTTP 503"):
        remote.read([3])
    http.fail[CHUNK.format(4)] = 403
    with pytest.raises(RemoteAccessError, match="HTTP 403"):
        remote.read([4])


def test_no_credentials_is_refused_at_once_naming_the_fix(s3, tmp_path, monkeypatch):
    """No S3 credentials anywhere: one RemoteAccessError naming the ways to give them, without
    the retries a network failure gets (CHRONOCL_REMOTE_RETRIES would make them slow)."""
    for name in [k for k in os.environ if k.startswith("AWS_")]:
        monkeypatch.delenv(name)
    monkeypatch.setenv("AWS_EC2_METADATA_DISABLED", "true")  # no instance metadata to ask
    monkeypatch.setenv("AWS_CONFIG_FILE", str(tmp_path / "none"))
    monkeypatch.setenv("AWS_SHARED_CREDENTIALS_FILE", str(tmp_path / "none"))
    monkeypatch.setenv("CHRONOCL_REMOTE_RETRIES", "2")
    monkeypatch.setenv("CHRONOCL_REMOTE_BACKOFF_S", "5")
    options = {"endpoint_url": s3.endpoint, "client_kwargs": {"region_name": "eu-west-1"}}
    t0 = time.perf_counter()
    with pytest.raises(RemoteAccessError) as info:
        chronocl.open(s3.url, storage_options=options)
    assert time.perf_counter() - t0 < 5  # retried, it would wait 5 + 10 s
    text = str(info.value)
    assert "no credentials were found" in text and "\n" not in text
    for fix in ("AWS_ACCESS_KEY_ID", "AWS_PROFILE", "--anon", "--storage-option"):
        assert fix in text


def test_bad_urls_and_buckets(http, s3):
    with pytest.raises(InputNotFoundError, match="no zarr store at http"):
        chronocl.open(http.url("nothing.zarr"))
    with pytest.raises(RemoteStoreError, match="cannot connect"):
        chronocl.open("http://127.0.0.1:9/s.zarr")  # the discard port: nothing listens
    with pytest.raises(InputNotFoundError, match=r"bucket 'no-such-bucket' .* does not exist"):
        chronocl.open("s3://no-such-bucket/s.zarr", storage_options=s3.storage_options())
    s3.check_credentials(True)
    try:
        with pytest.raises(RemoteAccessError, match=r"refused .*--anon"):
            chronocl.open(s3.url, storage_options=s3.storage_options("AKIAWRONGKEY", "nope"))
    finally:
        s3.check_credentials(False)


def test_storage_options_parse():
    assert parse_storage_options(["endpoint_url=http://h:9000", "use_ssl=false"], anon=True) == {
        "endpoint_url": "http://h:9000",
        "use_ssl": False,
        "anon": True,
    }
    with pytest.raises(InvalidParameterError, match="KEY=VALUE"):
        parse_storage_options(["novalue"])
    assert series_store("http://h/s.zarr", True, ["headers={}"]) == (
        "http://h/s.zarr",
        {"headers": {}},
    )
    with pytest.raises(InvalidParameterError, match=r"apply to http\(s\):// and s3:// stores"):
        series_store(__file__, anon=True)


def cli_all(*runs: list[str]) -> list[subprocess.CompletedProcess]:
    """Run several `chronocl` command lines at once (each a fresh process)."""
    env = {**env_without_aws(), "CHRONOCL_REMOTE_RETRIES": "1", "CHRONOCL_REMOTE_BACKOFF_S": "0"}
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "chronocl", *map(str, args)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for args in runs
    ]
    results = []
    for proc, args in zip(procs, runs, strict=True):
        out, err = proc.communicate(timeout=120)
        results.append(subprocess.CompletedProcess(args, proc.returncode, out, err))
    return results


def test_cli_reads_remote_stores_and_fails_in_one_line(served, http, s3, tmp_path):
    s3_opts = [
        f"--storage-option=endpoint_url={s3.endpoint}",
        "--storage-option=key=testing",
        "--storage-option=secret=testing",
        '--storage-option=client_kwargs={"region_name": "eu-west-1"}',
    ]
    shutil.copytree(served / "s.zarr", tmp_path / "t.zarr")
    chunk = tmp_path / "t.zarr/data/c/2/0/0/0"
    chunk.write_bytes(chunk.read_bytes()[:-7])
    http.root = tmp_path  # serve the damaged copy beside an intact one
    shutil.copytree(served / "s.zarr", tmp_path / "s.zarr")
    http.drop[CHUNK.format(4)] = 99
    integrate = ["integrate", "--engine", "numpy", "--mode", "max"]
    down = "--storage-option=endpoint_url=http://127.0.0.1:9"  # nothing listens there
    bad = {
        "refused": [*integrate, "http://127.0.0.1:9/s.zarr", tmp_path / "o1.zarr"],
        "dropped": [*integrate, http.url("s.zarr"), tmp_path / "o2.zarr"],
        "truncated": [*integrate, http.url("t.zarr"), tmp_path / "o3.zarr"],
        "bucket": [*integrate, "s3://no-bucket/s.zarr", tmp_path / "o4.zarr", *s3_opts],
        # an S3 endpoint that does not answer: the reads zarr started beside the failing one
        # printed 37-109 lines of 'Exception ignored in: <coroutine ...>' after the error
        "endpoint": [*integrate, s3.url, tmp_path / "o5.zarr", down, *s3_opts[1:]],
    }
    good = [
        [*integrate, s3.url, tmp_path / "s3.zarr", "--window", "0:4", *s3_opts],
        ["info", s3.public_url, "--json", "--anon", s3_opts[0]],
    ]
    results = cli_all(*bad.values(), *good)
    needles = {
        "refused": "cannot connect",
        "dropped": "connection dropped mid-read",
        "truncated": "chunk data/c/2/0/0/0 (step 2) cannot be decoded",
        "bucket": "bucket 'no-bucket'",
        "endpoint": "Could not connect to the endpoint URL",
    }
    for (name, args), result in zip(bad.items(), results, strict=False):
        assert result.returncode == 2, (name, result.stderr)
        lines = [line for line in result.stderr.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("chronocl: error:"), (name, lines)
        assert needles[name] in lines[0], (name, lines[0])
        assert not Path(args[args.index("max") + 2]).exists(), name
    assert partials(tmp_path) == []
    made, info = results[len(bad) :]
    assert made.returncode == 0, made.stderr
    expected = chronocl.integrate(
        chronocl.open(served / "s.zarr"), "0:4", mode="max", engine="numpy"
    )
    np.testing.assert_array_equal(
        chronocl.Chronovolume.load(tmp_path / "s3.zarr").rgba, expected.rgba
    )
    assert info.returncode == 0 and s3.public_url in info.stdout, info.stderr


def test_a_script_whose_s3_endpoint_is_down_gets_its_error_alone():
    """chronocl.open in a script: the exception, and no 'Exception ignored' from the reads
    given up beside it when the interpreter exits."""
    code = (
        "import chronocl, sys\n"
        "try:\n"
        "    chronocl.open('s3://b/s.zarr', storage_options={'endpoint_url': "
        "'http://127.0.0.1:9', 'key': 'k', 'secret': 's'})\n"
        "except chronocl.ChronoclError as e:\n"
        "    print(type(e).__name__, file=sys.stderr)\n"
    )
    env = {**env_without_aws(), "CHRONOCL_REMOTE_RETRIES": "1", "CHRONOCL_REMOTE_BACKOFF_S": "0"}
    env["AWS_EC2_METADATA_DISABLED"] = "true"
    run = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env
    )
    assert run.returncode == 0 and run.stderr.strip() == "RemoteStoreError", run.stderr


def test_local_paths_need_no_remote_libraries():
    """fsspec's HTTP and S3 filesystems load only when a URL is opened."""
    code = (
        "import sys, chronocl; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('s3fs', 'aiohttp', 'aiobotocore')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=os.environ, timeout=120
    )
    assert out.stdout.strip() == "[]", out.stderr


def test_omezarr_over_http_in_place(tmp_path):
    from .test_formats_omezarr import _write

    data = np.random.default_rng(7).random((3, 2, 8, 8, 8), dtype=np.float32)  # t, c, z, y, x
    _write(
        tmp_path / "img.ome.zarr",
        [data],
        "tczyx",
        [[2.0, 1.0, 0.5, 0.5, 0.5]],
        3,
        chunks=(1, 1, 8, 8, 8),
    )
    local = chronocl.open(tmp_path / "img.ome.zarr")
    with StoreServer(tmp_path) as server:
        remote = chronocl.open(server.url("img.ome.zarr"))
        assert remote.path is None and remote.source == local.source
        assert remote.times == local.times and remote.spacing == local.spacing
        np.testing.assert_array_equal(remote.read(range(3)), data[:, 0])
        np.testing.assert_array_equal(remote.variable("c1").read([2])[0], data[2, 1])


def test_the_viewer_shows_remote_stores(served, http, s3):
    """`chronocl view URL`: the viewer opens HTTP and S3 stores in place (named by the URL's
    stem, made unique), the same series as the local copy, and serves frames of them."""
    pytest.importorskip("websockets")
    from chronocl.viewer.datasets import open_datasets

    from .viewer_helpers import Client, start_server

    (local,) = open_datasets([served / "s.zarr"])
    remote = [
        *open_datasets([http.url("s.zarr"), http.url("s.zarr")]),
        *open_datasets([s3.url], s3.storage_options()),
    ]
    assert [d.name for d in remote] == ["s", "s-2", "s"]
    assert remote[0].path == http.url("s.zarr") and remote[2].path == s3.url
    for d in remote:
        same_series(d.series, local.series)
    server = start_server([http.url("s.zarr")])
    try:
        c = Client(server)
        ds, (_, header, images) = c.open(0)
        assert ds["name"] == "s" and len(ds["step_mean"]) == SHAPE[0]
        assert header["views"] and len(images) == 1 and len(images[0]) > 100
        c.close()
    finally:
        server.stop()
    bad = subprocess.run(
        [sys.executable, "-m", "chronocl", "view", str(served / "s.zarr"), "--anon"],
        capture_output=True,
        text=True,
        timeout=120,
        env=env_without_aws(),
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "--anon" in bad.stderr


def test_the_test_server_keeps_its_latency_and_bandwidth(served):
    """bench/remote.py's figures rest on the server's limits: a file takes at least its bytes
    over the rate plus the latency (a server that ignored either would pass the test above)."""
    import time
    import urllib.request

    biggest = max(
        (p for p in (served / "s.zarr").rglob("*") if p.is_file()), key=lambda p: p.stat().st_size
    )
    name = biggest.relative_to(served).as_posix()
    size = biggest.stat().st_size
    rate, latency = size / 0.2, 0.05  # 0.2 s of the link, 0.05 s before the first byte
    with StoreServer(served, latency_s=latency, bytes_per_s=rate) as slow:
        t = time.perf_counter()
        with urllib.request.urlopen(slow.url(name), timeout=30) as r:
            body = r.read()
        took = time.perf_counter() - t
    assert body == biggest.read_bytes()
    assert took >= 0.9 * (size / rate + latency), (took, size / rate + latency)
