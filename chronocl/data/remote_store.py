"""Stores over HTTP(S) and S3, read through zarr's `FsspecStore` with chronocl's checks.

`RemoteStore` is the remote twin of `chronocl.data.integrity.CheckedStore`: a chunk that the
store's metadata says must exist (``chunks: "complete"``) and that the server does not have
(HTTP 404, S3 NoSuchKey) is noted and reported as `StoreCorruptError` naming its key. A
network failure (refused or dropped connection, a timeout — over HTTP a read stalled for 60 s,
unless `client_kwargs` are given —, HTTP 5xx or 429) is retried with
exponential backoff, then raised as one `RemoteStoreError` naming the URL and the status; a
refusal (HTTP 401/403, S3 AccessDenied or unknown keys) is one `RemoteAccessError`. Neither is
ever read as zeros.

fsspec, aiohttp and s3fs are imported only when a URL is opened: local use pays nothing.
Credentials come the usual way (s3fs/botocore: environment, ``~/.aws`` profiles,
``AWS_PROFILE``); `storage_options` go to the fsspec filesystem as they are (``anon=True`` for
a public bucket, ``endpoint_url`` for MinIO and other S3-compatible servers).

Retries: ``CHRONOCL_REMOTE_RETRIES`` (default 3 retries after the first try) and
``CHRONOCL_REMOTE_BACKOFF_S`` (default 0.2 s, doubled each retry).

`parse_storage_options` reads the CLI's ``--storage-option k=v`` (values parsed as JSON where
they parse). An s3:// prefix with keys but no root metadata is a write that did not finish
(`incomplete_store`; `chronocl.data.remote_write` writes the root metadata last).
"""

from __future__ import annotations

import asyncio
import atexit
import json
import os
import re
import threading
import weakref
from collections.abc import Iterable, Mapping
from typing import Any
from urllib.parse import urlsplit

from chronocl.core import env
from chronocl.core.errors import (
    ChronoclError,
    InputNotFoundError,
    InvalidParameterError,
    RemoteAccessError,
    RemoteStoreError,
    StoreCorruptError,
)
from chronocl.core.tuning import TUNING
from chronocl.data.integrity import MissingChunks

SCHEMES = ("http://", "https://", "s3://")


def is_url(path: object) -> bool:
    """True for a store named by an http(s):// or s3:// URL (never for a local path)."""
    return isinstance(path, str) and path.lower().startswith(SCHEMES)


# A URL's scheme: two letters at least (`C://data` is a Windows drive, a path).
URL_SCHEME = re.compile(r"([A-Za-z][A-Za-z0-9+.-]+)://")


def check_url(path: object) -> object:
    """`path` as a store is opened: a URL checked and its scheme in lower case (http://,
    https://, s3://), anything else as it is; InvalidParameterError in one line, before
    anything is opened, for another scheme, a bad port, or no host or bucket."""
    text = path if isinstance(path, str) else None
    found = None if text is None else URL_SCHEME.match(text)
    if found is None:
        return path
    scheme = found[1].lower()
    if scheme + "://" not in SCHEMES:
        raise InvalidParameterError(
            f"cannot read a {scheme}:// store ({text!r}); chronocl reads a local path or an "
            "http://, https:// or s3:// URL"
        )
    url = scheme + text[len(found[1]) :]
    try:
        parts = urlsplit(url)  # (an unclosed IPv6 bracket raises)
        parts.port  # noqa: B018 (a port that is not a number raises)
    except ValueError as exc:
        raise InvalidParameterError(f"{text!r} is not a URL ({exc}); check it") from None
    if not parts.hostname:
        what = "bucket" if scheme == "s3" else "host"
        raise InvalidParameterError(f"{text!r} names no {what}; check the URL")
    return url


def check_storage_options(path: object, storage_options: object) -> None:
    """Storage options apply to a store's URL only: InvalidParameterError in one line for
    options that are not a dict, or given with a local path or an array (they were ignored)."""
    if storage_options is None:
        return
    if not isinstance(storage_options, Mapping):
        raise InvalidParameterError(
            f"storage_options must be a dict (as chronocl.open takes them), not "
            f"{type(storage_options).__name__}"
        )
    if storage_options and not is_url(path):
        what = (
            f"the local path {str(path)!r}"
            if isinstance(path, str | os.PathLike)
            else (f"a {type(path).__name__}")
        )
        raise InvalidParameterError(
            f"storage_options apply to a store's http(s):// or s3:// URL, not to {what}"
        )


def retry_policy() -> tuple[int, float]:
    """(retries after the first try, first backoff in seconds), from the environment."""
    try:
        retries = int(env.get("CHRONOCL_REMOTE_RETRIES") or TUNING.remote_retries)
        backoff = float(env.get("CHRONOCL_REMOTE_BACKOFF_S") or TUNING.remote_backoff_s)
    except ValueError:
        raise InvalidParameterError(
            "CHRONOCL_REMOTE_RETRIES must be a whole number and CHRONOCL_REMOTE_BACKOFF_S a "
            "number of seconds"
        ) from None
    return max(0, retries), max(0.0, backoff)


class Url(str):
    """A store's URL, without a trailing slash, with a path's `name` (its last part)."""

    def __new__(cls, url: object) -> Url:
        return super().__new__(cls, str(url).rstrip("/"))

    @property
    def name(self) -> str:
        return self.rsplit("/", 1)[-1]


def join(url: str, key: str) -> str:
    """`key` under the store URL `url`."""
    return f"{url.rstrip('/')}/{key}" if key else url.rstrip("/")


class RemoteStore(MissingChunks):
    """Built by `remote_store`: a read-only `FsspecStore` with the checks of `MissingChunks`,
    retries with backoff and one-line errors (the class mixes into FsspecStore lazily, so
    importing this module imports no fsspec)."""

    url: str
    storage_options: dict

    def setup(self, url: str, storage_options: dict, arrays: tuple[str, ...]) -> None:
        """Note the URL and options the store was opened with; check the chunks of `arrays`."""
        self._init_checks(url, arrays)
        self.url, self.storage_options = url, storage_options

    async def get(self, key, prototype=None, byte_range=None):
        task = asyncio.current_task()
        if task is not None:
            with _reads_lock:
                _reads.add(task)
        retries, backoff = retry_policy()
        for attempt in range(retries + 1):
            try:
                buf = await super().get(key, prototype, byte_range)  # type: ignore[misc]
                break
            except ChronoclError:
                raise
            except Exception as exc:
                failure = classify(exc)
                if failure is None:
                    raise
                refused, status = failure
                where = join(self.url, key)
                if refused:
                    raise access_error(where, status) from None
                if attempt == retries:
                    tries = f"{retries + 1} tries" if retries else "1 try"
                    raise RemoteStoreError(
                        f"reading {where} failed after {tries}: {status}; check the URL and "
                        "the network (CHRONOCL_REMOTE_RETRIES sets the retries)"
                    ) from None
                await asyncio.sleep(backoff * 2**attempt)
        self._note(key, buf)
        return buf

    def __reduce__(self):  # for dask.distributed workers
        return _rebuild, (self.url, self.storage_options, self.arrays, self.complete, self.may_miss)


def _rebuild(url, options, arrays, complete, may_miss):
    store = remote_store(url, options, arrays)
    store.complete, store.may_miss = complete, may_miss
    return store


_classes: dict[str, type] = {}


def remote_store(
    url: str, storage_options: Mapping[str, Any] | None = None, arrays: tuple[str, ...] = ("data",)
):
    """A read-only checked store at `url` (http(s):// or s3://) with `storage_options`."""
    if "fsspec" not in _classes:
        from zarr.storage import FsspecStore

        _classes["fsspec"] = type("RemoteFsspecStore", (RemoteStore, FsspecStore), {})
        atexit.register(settle)  # before zarr's own clean-up (registered at its import)
    options = dict(storage_options or {})
    url = url.rstrip("/")
    try:
        if url.lower().startswith(("http://", "https://")) and "client_kwargs" not in options:
            import aiohttp

            # A stalled server is a network failure (retried), not a read waiting for minutes.
            options["client_kwargs"] = {
                "timeout": aiohttp.ClientTimeout(total=None, sock_connect=15, sock_read=60)
            }
        store = _classes["fsspec"].from_url(url, storage_options=options, read_only=True)
    except ImportError as exc:
        raise InvalidParameterError(
            f"reading {url} needs {exc.name or 'fsspec'}; install chronocl with its remote "
            "dependencies (pip install 'fsspec[http]' s3fs)"
        ) from None
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(f"cannot open {url}: {exc}; check --storage-option") from None
    store.setup(url, options, arrays)
    return store


_reads: weakref.WeakSet = weakref.WeakSet()  # the tasks that read a remote store (`settle`)
_reads_lock = threading.Lock()
NO_CREDENTIALS = ("NoCredentialsError", "PartialCredentialsError", "CredentialRetrievalError")


def classify(exc: BaseException) -> tuple[bool, str] | None:
    """(refused, status) of a remote read's failure; None for an error that is not the
    network's or the server's (a bug, which is raised as it is)."""
    status = getattr(exc, "status", None)
    name = type(exc).__name__
    if isinstance(exc, PermissionError):
        return True, _short(exc)
    if name == "NoCredentialsError":  # botocore's: nothing to retry, nothing the network fixes
        return True, "no credentials were found"
    if name in NO_CREDENTIALS:
        return True, _short(exc)
    if isinstance(status, int):  # aiohttp's ClientResponseError
        message = getattr(exc, "message", "") or ""
        text = f"HTTP {status} {message}".strip()
        return status in (401, 403), text
    if name == "ClientPayloadError" or "ContentLengthError" in name:
        return False, f"the connection dropped mid-read ({_short(exc)})"
    if "Connector" in name or isinstance(exc, ConnectionError):
        return False, f"cannot connect ({_short(exc)})"
    if isinstance(exc, asyncio.TimeoutError | TimeoutError):
        return False, "timed out"
    module = type(exc).__module__ or ""
    if isinstance(exc, OSError) or module.startswith(("aiohttp", "botocore", "aiobotocore")):
        return False, _short(exc)
    return None


def access_error(where: str, status: str) -> RemoteAccessError:
    """The one line for a store that refuses access."""
    fix = (
        "check the credentials and what they may read (AWS_ACCESS_KEY_ID and "
        "AWS_SECRET_ACCESS_KEY, or AWS_PROFILE; or --storage-option key=... secret=...); "
        "--anon reads a public bucket"
        if where.lower().startswith("s3://")
        else "check the URL and the credentials the server wants (--storage-option headers={...})"
    )
    return RemoteAccessError(f"access to {where} was refused ({status}); {fix}")


def settle(timeout: float | None = None) -> None:
    """Cancel the remote reads still running and let them unwind on their own event loop.

    zarr reads several keys at once; when one fails, the others go on (retrying), and at
    exit the interpreter closes their loop under them: each then printed 'Exception ignored
    in: <coroutine object RemoteStore.get>' with a traceback (aiobotocore resets a context
    variable from another context), 37-109 lines after the error's one line. It runs at exit
    (registered when the first remote store is opened), and a command that stops on an error
    calls it first. Only the tasks reading a remote store are cancelled (`_reads`), each
    waited for `timeout` seconds at most (None: `TUNING.remote_settle_s`)."""
    timeout = TUNING.remote_settle_s if timeout is None else timeout
    with _reads_lock:
        pending = [t for t in _reads if not t.done()]
    by_loop: dict = {}
    for task in pending:
        by_loop.setdefault(task.get_loop(), []).append(task)
    for loop, tasks in by_loop.items():
        if loop.is_closed() or not loop.is_running():
            continue

        async def cancel(tasks=tasks) -> None:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

        done = asyncio.run_coroutine_threadsafe(cancel(), loop)
        try:
            done.result(timeout)
        except Exception:  # a loop stopping or stuck meanwhile: cancel nothing later instead
            done.cancel()


def missing_store(url: str, storage_options: Mapping[str, Any] | None) -> ChronoclError:
    """The one line for a URL where no zarr metadata was found: for S3, whether the bucket
    itself is missing, refused or the key is wrong."""
    if url.lower().startswith("s3://"):
        bucket = url[5:].split("/", 1)[0]
        try:
            import s3fs

            fs = s3fs.S3FileSystem(**dict(storage_options or {}))
            fs.ls(bucket)  # NoSuchBucket -> FileNotFoundError, wrong keys -> PermissionError
        except FileNotFoundError:
            return InputNotFoundError(
                f"bucket {bucket!r} of {url} does not exist; check the bucket's name "
                "(and --storage-option endpoint_url=... for a server other than AWS)"
            )
        except PermissionError as exc:
            return access_error(f"s3://{bucket}", _short(exc))
        except Exception as exc:
            failure = classify(exc)
            if failure is None:
                raise
            return RemoteStoreError(f"reading s3://{bucket} failed: {failure[1]}")
        partial = incomplete_store(url, storage_options)  # keys, but the root metadata missing
        if partial is not None:
            return partial
    return InputNotFoundError(
        f"no zarr store at {url} (neither zarr.json nor .zarray/.zgroup found); check the URL"
    )


def parse_storage_options(items: Iterable[str] | None, anon: bool = False) -> dict[str, Any]:
    """``k=v`` strings as fsspec storage options; `anon` adds ``anon=True`` (a public bucket)."""
    options: dict[str, Any] = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise InvalidParameterError(
                f"--storage-option {item!r} must be KEY=VALUE, e.g. "
                "endpoint_url=http://localhost:9000"
            )
        try:
            options[key] = json.loads(value)
        except ValueError:
            options[key] = value
    if anon:
        options["anon"] = True
    return options


def filesystem(storage_options: Mapping[str, Any] | None):
    """An s3fs filesystem with `storage_options` (its listings not cached: writes change them)."""
    try:
        import s3fs
    except ImportError as exc:
        raise InvalidParameterError(
            f"writing to s3:// needs {exc.name or 's3fs'}; pip install s3fs"
        ) from None
    try:
        return s3fs.S3FileSystem(
            **dict(storage_options or {}), skip_instance_cache=True, use_listings_cache=False
        )
    except (TypeError, ValueError) as exc:
        raise InvalidParameterError(
            f"cannot use the S3 options: {exc}; check --storage-option"
        ) from None


def incomplete_store(url: str, storage_options: Mapping[str, Any] | None) -> ChronoclError | None:
    """StoreCorruptError for an s3:// store that has keys but no root metadata (its write did
    not finish); None where the prefix is empty (or cannot be listed)."""
    if not url.lower().startswith("s3://"):
        return None
    try:
        fs = filesystem(storage_options)
        found = fs.ls(url[5:].rstrip("/"), detail=False)  # one level: bounded
    except Exception:  # FileNotFoundError: nothing there
        return None
    if not found:
        return None
    return StoreCorruptError(
        f"store {url} is incomplete: it has keys but no root zarr.json, which "
        "chronocl writes last; a write to it did not finish, so write it again (--overwrite)"
    )


def _short(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if len(text) > 160:
        text = text[:157] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
