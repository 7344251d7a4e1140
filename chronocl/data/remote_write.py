"""Writes to s3:// stores: built whole, then published so that readers never see a partial one.

S3 has no rename, so the local scheme (`chronocl.core.atomic`: a hidden sibling renamed when
complete) becomes: the output is written, atomically as ever, into a private local staging
folder (``CHRONOCL_TMPDIR`` or the system's temporary folder; it needs room for the output),
then uploaded under its URL with the **markers last**: the files at the output's root that
name what it is (a zarr store's root ``zarr.json`` / ``.zgroup`` / ``.zattrs``, a .pvd or
.json manifest). A zarr store is opened from its root metadata, so until the last upload
`chronocl.open` and `Chronovolume.load` find no store there and say it is incomplete
(`chronocl.data.remote_store.incomplete_store`), never read a part of it. A one-file output is
one PUT, which S3 makes visible whole or not at all.

A failed or interrupted write (an exception, Ctrl-C, a refused upload) removes its staging
folder and every key it uploaded; nothing of the user's that existed before is touched unless
``overwrite``: then the old output is removed only once the new one is completely written
(staged), its root metadata first, so the URL reads as the old output, then as incomplete
(refused) for the upload's duration, then as the new one, never as a mix. If that upload
fails the old output is gone and the URL is left empty, which the error says. (A writer killed
outright, kill -9, can leave the keys it uploaded so far; they hold no root metadata and read
as incomplete until written again with ``--overwrite``.)
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from chronocl.core import env
from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    InvalidParameterError,
    OutputExistsError,
    OutputIsInputError,
    RemoteAccessError,
    RemoteStoreError,
)
from chronocl.core.tuning import TUNING
from chronocl.data.remote_store import Url, classify, filesystem, is_url, parse_storage_options

ROOT_MARKERS = ("zarr.json", ".zgroup", ".zattrs", ".zarray", ".zmetadata")
MANIFEST_SUFFIXES = (".json", ".pvd")  # written last too: they list what the output holds


def split_url(url: str) -> tuple[str, str]:
    """(bucket, key) of an s3:// URL, checked to be one this module can write."""
    if not url.lower().startswith("s3://"):
        raise InvalidParameterError(
            f"cannot write to {url}: outputs go to a local path or an s3:// URL (HTTP servers "
            "take no writes)"
        )
    bucket, _, key = url[5:].strip("/").partition("/")
    if not bucket or not key:
        raise InvalidParameterError(
            f"output {url} names no key inside the bucket; give s3://BUCKET/NAME.zarr"
        )
    return bucket, key


def _failure(url: str, exc: BaseException, doing: str) -> ChronoclError:
    """The one-line error for a refused or failed request while `doing` something to `url`."""
    if isinstance(exc, ChronoclError):
        return exc
    failure = classify(exc)
    if failure is None:
        raise exc
    refused, status = failure
    if refused:
        return RemoteAccessError(
            f"writing to {url} was refused ({status}); check the credentials "
            "(AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY or AWS_PROFILE): they must allow "
            "s3:PutObject and s3:DeleteObject there"
        )
    return RemoteStoreError(f"{doing} {url} failed: {status}; check the URL and the network")


def check_remote_output(
    url: str,
    overwrite: bool,
    storage_options: Mapping[str, Any] | None = None,
    inputs: tuple[object, ...] = (),
) -> bool:
    """Every check of an s3:// output before any work: apart from the `inputs` (URLs; local
    paths are apart anyway), the bucket exists and lets us in, and the output does not exist
    unless `overwrite`. Returns whether it exists."""
    bucket, key = split_url(url)
    here = f"s3://{bucket}/{key}".rstrip("/") + "/"
    for item in inputs:
        if not is_url(str(item)) or not str(item).lower().startswith("s3://"):
            continue
        there = "s3://" + str(item)[5:].strip("/") + "/"
        if here.startswith(there) or there.startswith(here):
            where = (
                "the input"
                if here == there
                else ("inside the input" if here.startswith(there) else "around the input")
            )
            raise OutputIsInputError(f"output {url} is {where} {item}; write the output elsewhere")
    fs = filesystem(storage_options)
    try:
        fs.call_s3("head_bucket", Bucket=bucket)  # 404 -> FileNotFoundError, 403 -> Permission
    except FileNotFoundError:
        raise InputNotFoundError(
            f"bucket {bucket!r} of the output {url} does not exist; create it first, or check "
            "its name (and --storage-option endpoint_url=... for a server other than AWS)"
        ) from None
    except Exception as exc:
        raise _failure(f"s3://{bucket}", exc, "listing") from None
    try:
        exists = bool(fs.exists(f"{bucket}/{key}"))
    except Exception as exc:
        raise _failure(url, exc, "checking") from None
    if exists and not overwrite:
        raise OutputExistsError(
            f"output {url} already exists; pass --overwrite (overwrite=True) to replace it"
        )
    return exists


@contextlib.contextmanager
def remote_output(
    url: str, overwrite: bool = False, storage_options: Mapping[str, Any] | None = None
) -> Iterator[Path]:
    """Yield a fresh local path to write the output to; publish it at `url` when the block
    succeeds (markers last), remove it and whatever was uploaded when it does not."""
    url = Url(url)
    check_remote_output(url, overwrite, storage_options)
    where = env.get("CHRONOCL_TMPDIR") or None
    staging = Path(tempfile.mkdtemp(prefix="chronocl-upload-", dir=where))
    try:
        local = staging / url.name
        yield local
        if os.path.lexists(local):
            publish(local, url, storage_options, overwrite)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def output_path(
    out: str | os.PathLike,
    overwrite: bool = False,
    storage_options: Mapping[str, Any] | None = None,
) -> Iterator[Path | str]:
    """Where to write the output `out`: itself when local (str kept), else a staging path
    published to the URL when the block succeeds (`remote_output`)."""
    if is_url(str(out)):
        with remote_output(str(out), overwrite, storage_options) as local:
            yield local
    else:
        if storage_options:
            raise InvalidParameterError(
                f"--storage-option applies to s3:// outputs, not to the local path {str(out)!r}"
            )
        yield out


def publish(
    local: Path, url: str, storage_options: Mapping[str, Any] | None, overwrite: bool
) -> None:
    """Upload the finished output `local` (file or folder) to `url`, markers last."""
    bucket, key = split_url(url)
    target = f"{bucket}/{key}"
    fs = filesystem(storage_options)
    if not overwrite and fs.exists(target):  # written by someone else while this run ran
        raise OutputExistsError(f"{url} appeared while this run wrote it; nothing was uploaded")
    if local.is_file():
        try:
            if overwrite and fs.isdir(target):
                _remove_old(fs, target)
            fs.put_file(str(local), target)  # one PUT: visible whole or not at all
        except BaseException as exc:
            if isinstance(exc, Exception):
                raise _failure(url, exc, "uploading") from None
            raise
        return
    files = sorted(p for p in local.rglob("*") if p.is_file())
    last = [p for p in files if p.parent == local and _is_marker(p.name)]
    first = [p for p in files if p not in last]
    removed_old = False
    keys = [f"{target}/{p.relative_to(local).as_posix()}" for p in (*first, *last)]
    try:
        if overwrite and fs.exists(target):
            _remove_old(fs, target)
            removed_old = True
        for batch in (first, last):
            upload(fs, [(p, f"{target}/{p.relative_to(local).as_posix()}") for p in batch])
    except BaseException as exc:
        _clean(fs, target if removed_old else keys)  # only this run's keys beside others
        if isinstance(exc, Exception):
            error = _failure(url, exc, "uploading to")
            if removed_old:
                error = type(error)(f"{error}; the old output there was already removed")
            raise error from None
        raise


def upload(fs, pairs: list[tuple[Path, str]]) -> None:
    """PUT each (local file, key) of `pairs`, TUNING.upload_concurrency at a time: threads calling
    s3fs's `put_file`, whose requests share its event loop. Interrupted (Ctrl-C, an error), the
    uploads not yet started are dropped and those in flight waited for (up to 60 s) before this
    returns, so that the cleanup that follows is not outrun by a late PUT."""
    if not pairs:
        return
    pool = concurrent.futures.ThreadPoolExecutor(TUNING.upload_concurrency, "chronocl-upload")
    pending = {pool.submit(fs.put_file, str(path), key) for path, key in pairs}
    try:
        while pending:  # short waits, so Ctrl-C lands here
            done, pending = concurrent.futures.wait(
                pending, 0.25, concurrent.futures.FIRST_EXCEPTION
            )
            for future in done:
                future.result()  # the first failure is raised
    finally:
        pool.shutdown(wait=False, cancel_futures=True)  # those not started: never done
        concurrent.futures.wait([f for f in pending if not f.cancelled()], 60)


def _is_marker(name: str) -> bool:
    return name in ROOT_MARKERS or name.endswith(MANIFEST_SUFFIXES)


def _remove_old(fs, target: str) -> None:
    """Remove the output at `target`: its root metadata first, so it reads as incomplete at
    once, then the rest."""
    if fs.isfile(target):
        fs.rm_file(target)
        return
    roots = [f"{target}/{name}" for name in ROOT_MARKERS]
    present = [k for k in roots if fs.exists(k)]
    if present:
        fs.rm(present)
    fs.rm(target, recursive=True)


def _clean(fs, written: str | list[str]) -> None:
    """Remove what a failed upload wrote: the keys it PUT, or the whole `target` it had
    emptied first (best effort: the write's error matters)."""
    with contextlib.suppress(Exception):
        if isinstance(written, str):
            fs.rm(written, recursive=True)
        else:
            fs.rm([k for k in written if fs.exists(k)])


def split_storage_options(
    store: object, out: object, anon: bool, storage_option: list[str] | None
) -> tuple[tuple[bool, list[str] | None], dict[str, Any]]:
    """The CLI's ``--anon`` / ``--storage-option`` shared by STORE and OUT: (anon, items) to
    read STORE with (`chronocl.cli.options.series_store`), and the options to write an s3://
    OUT with (the same ``--storage-option``s, never ``--anon``: writes are signed)."""
    if not is_url(str(out)):
        return (anon, storage_option), {}
    out_options = parse_storage_options(storage_option)
    if is_url(str(store)):
        return (anon, storage_option), out_options
    if anon:
        raise InvalidParameterError(
            "--anon reads an s3:// STORE of a public bucket; writes to an s3:// OUT are signed "
            "(give credentials, not --anon)"
        )
    return (False, None), out_options
