"""Writes to s3:// (moto's S3 in server mode on loopback, no mocks): `ingest`, `integrate` and
`export` publish an output whole, root metadata last, equal to what they write locally; a run
that fails leaves nothing readable and no key behind; an existing output is refused before any
work unless --overwrite.
"""

from __future__ import annotations

import io
import json
import logging
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import chronocl
from chronocl.core.errors import (
    InputNotFoundError,
    InvalidDataError,
    InvalidParameterError,
    OutputExistsError,
    RemoteAccessError,
    StoreCorruptError,
)
from chronocl.data.formats.export import export_series
from chronocl.data.formats.outputs import save_chronovolume
from chronocl.data.ingest import ingest
from chronocl.data.level_sources import POOLED
from chronocl.data.level_writer import add_levels
from chronocl.data.remote import add_remote_levels
from chronocl.data.remote_levels import RemoteLevels
from chronocl.data.remote_write import output_path, split_storage_options
from chronocl.data.verify import verify
from chronocl.data.writer import write_store

from .remote_servers import S3Server, env_without_aws

pytest.importorskip("s3fs")
pytest.importorskip("moto.server")

SHAPE = (4, 16, 16, 80)  # the longest axis above 64: the store has one coarse level
BUCKET = "out"


@pytest.fixture(scope="module")
def s3():
    logging.getLogger("werkzeug").setLevel(logging.ERROR)
    with S3Server() as server:
        server.filesystem().mkdir(BUCKET)
        server.opts = [
            f"--storage-option=endpoint_url={server.endpoint}",
            "--storage-option=key=testing",
            "--storage-option=secret=testing",
            '--storage-option=client_kwargs={"region_name": "eu-west-1"}',
        ]
        yield server


@pytest.fixture(scope="module")
def npy(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("in") / "a.npy"
    np.save(path, np.random.default_rng(5).random(SHAPE, dtype=np.float32))
    return path


def cli_all(*runs: list, tmpdir: Path | None = None) -> list[subprocess.CompletedProcess]:
    """Run several `chronocl` command lines at once (each a fresh process)."""
    env = {**env_without_aws(), "CHRONOCL_REMOTE_RETRIES": "1", "CHRONOCL_REMOTE_BACKOFF_S": "0"}
    if tmpdir is not None:
        env["CHRONOCL_TMPDIR"] = str(tmpdir)
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


def one_line(result: subprocess.CompletedProcess, needle: str) -> None:
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("chronocl: error:"), lines
    assert needle in lines[0], lines[0]


def keys(s3: S3Server, url: str) -> dict[str, str]:
    """ETag of every key under `url` (empty where there is none)."""
    fs = s3.filesystem()
    path = url.removeprefix("s3://")
    return {k: v["ETag"] for k, v in fs.find(path, detail=True).items()}


def test_ingest_integrate_export_to_s3_equal_local(s3, npy, tmp_path, monkeypatch):
    staging = tmp_path / "staging"
    staging.mkdir()
    local = ingest([npy], tmp_path / "a.zarr")
    (made,) = cli_all(["ingest", npy, "-o", f"s3://{BUCKET}/a.zarr", *s3.opts], tmpdir=staging)
    assert made.returncode == 0, made.stderr
    url = f"s3://{BUCKET}/a.zarr"
    integrate = ["integrate", "--engine", "numpy", "--mode", "max", "--window", "0:4"]
    runs = cli_all(
        [*integrate, url, f"s3://{BUCKET}/m.zarr", *s3.opts],
        ["export", url, "-o", f"s3://{BUCKET}/e.npy", "--format", "npy", "--z", "2:9", *s3.opts],
        tmpdir=staging,
    )
    for result in runs:
        assert result.returncode == 0, (result.args, result.stderr)
    options = s3.storage_options()
    # What the CLI does for other outputs: a one-file chronovolume, a folder with a manifest.
    monkeypatch.setenv("CHRONOCL_TMPDIR", str(staging))
    with output_path(f"s3://{BUCKET}/m.vti", False, options) as out:
        save_chronovolume(chronocl.integrate(local, "0:4", mode="max", engine="numpy"), out)
    with output_path(f"s3://{BUCKET}/e-vti", False, options) as out:
        export_series(local, out, fmt="vti", window="1:3")
    assert list(staging.iterdir()) == []  # the staging folders are gone
    remote = chronocl.open(url, storage_options=options)
    assert remote.stats == local.stats and remote.n_levels == local.n_levels == 2
    np.testing.assert_array_equal(remote.read(range(4)), local.read(range(4)))
    np.testing.assert_array_equal(remote.level(1).read([0, 3]), local.level(1).read([0, 3]))

    want = chronocl.integrate(local, "0:4", mode="max", engine="numpy")
    got = chronocl.Chronovolume.load(f"s3://{BUCKET}/m.zarr", storage_options=options)
    np.testing.assert_array_equal(got.rgba, want.rgba)
    np.testing.assert_array_equal(got.t_index, want.t_index)
    (shown,) = cli_all(["info", f"s3://{BUCKET}/m.zarr", "--json", *s3.opts])
    assert shown.returncode == 0, shown.stderr  # it said "has no array 'data'"
    summary = json.loads(shown.stdout)
    assert summary["shape (Z, Y, X)"] == list(want.shape) and summary["spec"]["mode"] == "max"

    fs = s3.filesystem()
    export_series(local, tmp_path / "e.npy", fmt="npy", z="2:9")
    assert fs.cat(f"{BUCKET}/e.npy") == (tmp_path / "e.npy").read_bytes()
    np.testing.assert_array_equal(
        np.load(io.BytesIO(fs.cat(f"{BUCKET}/e.npy"))), local.read(range(4))[:, 2:9]
    )
    export_series(local, tmp_path / "e-vti", fmt="vti", window="1:3")
    exported = sorted(p.name for p in (tmp_path / "e-vti").iterdir())
    assert sorted(k.rsplit("/", 1)[-1] for k in fs.find(f"{BUCKET}/e-vti")) == exported
    assert fs.isfile(f"{BUCKET}/m.vti")  # one PUT: a one-file output appears whole
    assert verify(f"s3://{BUCKET}/m.zarr", storage_options=options)["status"] == "ok"


def test_existing_output_refused_before_work_and_overwrite_replaces(s3, npy, tmp_path):
    url = f"s3://{BUCKET}/x.zarr"
    ingest([npy], url, storage_options=s3.storage_options())
    before = keys(s3, url)
    bad = np.zeros(SHAPE, np.float32)
    np.save(tmp_path / "zeros.npy", bad)
    runs = cli_all(
        ["ingest", tmp_path / "zeros.npy", "-o", url, *s3.opts],
        ["integrate", "--engine", "numpy", url, f"{url}/m.zarr", "--overwrite", *s3.opts],
        ["verify", url, *s3.opts],  # verify reads s3:// too
        ["pyramid", url, *s3.opts],
    )
    one_line(runs[0], f"output {url} already exists; pass --overwrite")
    one_line(runs[1], "inside the input")
    assert runs[2].returncode == 0 and "ok" in runs[2].stdout, runs[2].stderr
    assert runs[3].returncode == 0 and "levels already present" in runs[3].stdout, runs[3].stderr
    assert keys(s3, url) == before  # untouched
    options = s3.storage_options()
    with pytest.raises(InputNotFoundError, match="bucket 'no-bucket' of the output"):
        ingest([npy], "s3://no-bucket/x.zarr", storage_options=options)
    s3.check_credentials(True)
    try:
        wrong = s3.storage_options(key="wrong", secret="wrong")
        with pytest.raises(RemoteAccessError, match=f"writing to s3://{BUCKET} was refused"):
            ingest([npy], f"s3://{BUCKET}/z.zarr", storage_options=wrong)
    finally:
        s3.check_credentials(False)
    with pytest.raises(InvalidParameterError, match="outputs go to a local path or an s3://"):
        ingest([npy], "http://127.0.0.1:9/x.zarr")
    with pytest.raises(InvalidParameterError, match="writes to an s3:// OUT are signed"):
        split_storage_options(npy, url, True, None)
    with pytest.raises(OutputExistsError, match="already exists"):
        ingest([tmp_path / "zeros.npy"], url, storage_options=s3.storage_options())
    ingest([tmp_path / "zeros.npy"], url, overwrite=True, storage_options=s3.storage_options())
    replaced = chronocl.open(url, storage_options=s3.storage_options())
    assert replaced.stats.vmax == 0.0 and not replaced.read([3]).any()
    assert set(keys(s3, url)) == set(before)  # the same layout, all of it new
    assert keys(s3, url) != before


def test_failed_runs_leave_nothing_readable(s3, npy, tmp_path, monkeypatch):
    staging = tmp_path / "staging"
    staging.mkdir()
    options = s3.storage_options()
    # A bad input found late: the last step holds a NaN.
    data = np.load(npy)
    data[-1, 3, 3, 3] = np.nan
    np.save(tmp_path / "nan.npy", data)
    monkeypatch.setenv("CHRONOCL_TMPDIR", str(staging))
    with pytest.raises(InvalidDataError, match="NaN/infinite values"):
        ingest([tmp_path / "nan.npy"], f"s3://{BUCKET}/nan.zarr", storage_options=options)
    assert keys(s3, f"s3://{BUCKET}/nan.zarr") == {} and list(staging.iterdir()) == []
    with pytest.raises(InputNotFoundError, match="no zarr store"):
        chronocl.open(f"s3://{BUCKET}/nan.zarr", storage_options=options)

    # Interrupted mid-upload (Ctrl-C): what it uploaded is removed.
    many = np.random.default_rng(1).random((100, 16, 16, 80), dtype=np.float32)
    np.save(tmp_path / "many.npy", many)
    url = f"s3://{BUCKET}/cut.zarr"
    env = {**env_without_aws(), "CHRONOCL_TMPDIR": str(staging)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "chronocl", "ingest", tmp_path / "many.npy", "-o", url, *s3.opts],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    fs = s3.filesystem()
    deadline = time.monotonic() + 60
    while not fs.find(url[5:]) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert proc.poll() is None, "the upload ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode != 0, err
    assert keys(s3, url) == {} and list(staging.iterdir()) == []


def test_a_store_without_root_metadata_reads_as_incomplete(s3, npy, tmp_path):
    """What a writer killed outright (kill -9) mid-upload leaves: keys, no root zarr.json."""
    options = s3.storage_options()
    for url, what in (
        (f"s3://{BUCKET}/half.zarr", "series"),
        (f"s3://{BUCKET}/half-cv.zarr", "chronovolume"),
    ):
        if what == "series":
            ingest([npy], url, storage_options=options)
        else:
            series = ingest([npy], tmp_path / "l.zarr")
            chronocl.integrate(series, "0:2", mode="max", engine="numpy").save(url, False, options)
        s3.filesystem().rm_file(f"{url[5:]}/zarr.json")
        with pytest.raises(StoreCorruptError, match=f"store {url} is incomplete"):
            if what == "series":
                chronocl.open(url, storage_options=options)
            else:
                chronocl.Chronovolume.load(url, storage_options=options)


def test_pyramid_adds_levels_to_an_s3_store(s3, npy, tmp_path):
    options = s3.storage_options()
    data = np.load(npy)
    write_store(
        tmp_path / "bare.zarr", list(data), n_steps=4, volume_shape=SHAPE[1:], dtype=np.float32,
        levels=False,
    )  # fmt: skip
    url = s3.put(tmp_path / "bare.zarr", BUCKET, "bare.zarr")
    # Keys of a build killed mid-upload: no levels/zarr.json, so no levels to readers.
    s3.filesystem().pipe(f"{BUCKET}/bare.zarr/levels/1/max/c.0.0.0.0", b"junk")
    assert chronocl.open(url, storage_options=options).level_source is POOLED
    summary = add_remote_levels(url, options)
    assert summary["status"] == "added"
    remote = chronocl.open(url, storage_options=options)
    assert isinstance(remote.level_source, RemoteLevels)
    add_levels(tmp_path / "bare.zarr")
    local = chronocl.open(tmp_path / "bare.zarr")
    for pool in ("mean", "max"):
        np.testing.assert_array_equal(
            remote.level(1, pool).read(range(4)), local.level(1, pool).read(range(4))
        )
    assert add_remote_levels(url, options)["status"].startswith("levels already present")
    assert add_remote_levels(url, options, force=True)["status"] == "rebuilt"
    assert verify(url, storage_options=options)["status"] == "ok"
