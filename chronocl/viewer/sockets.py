"""One client's WebSocket: the `info` message first, then the protocol loop.

Each message is validated (`protocol.parse_message`) and handed to the client's
`ClientWorker`; an immediate reply (`dataset`) is sent at once, frames and task replies come
from the worker's thread through `send_from_thread`. Errors in a message are answered and
the socket stays up; nothing sent to a client carries a traceback.

`info_message`, `handle`, `error_reply` and `answer` are the socket's protocol without the
socket: a notebook widget (chronocl.notebook) serves its comm with them.
"""

from __future__ import annotations

import asyncio
import json
import threading

from chronocl.core.tuning import TUNING
from chronocl.viewer.datasets import Dataset
from chronocl.viewer.errors import error_text
from chronocl.viewer.progress import refine_progress
from chronocl.viewer.protocol import ProtocolError, choices, parse_message, request_id
from chronocl.viewer.residency import report_steps
from chronocl.viewer.saving import Downloads
from chronocl.viewer.view_sessions import SharedSteps
from chronocl.viewer.worker import ClientWorker


def info_message(datasets: list[Dataset]) -> dict:
    """The first message on every socket: the data sets and everything the page may choose
    from (modes from the registry, orders, presets, defaults, bounds)."""
    return {
        "type": "info",
        "datasets": [
            {"index": i, "name": d.name, "shape": list(d.series.shape)}
            for i, d in enumerate(datasets)
        ],
        **choices(),
    }


def handle(worker: ClientWorker, msg: dict) -> dict | None:
    """Apply one validated message; returns an immediate reply, if any."""
    kind = msg["type"]
    if kind == "open":
        return {
            "type": "dataset",
            "id": msg.get("id"),
            **worker.open(msg["dataset"], msg.get("id"), msg.get("fit", True)),
        }
    if kind == "load":
        return {
            "type": "dataset",
            "id": msg.get("id"),
            **worker.load(msg["session"], msg.get("id")),
        }
    if kind == "update":
        worker.update(msg)
        return None
    if kind == "cancel":
        worker.cancel_refine()
        return {**refine_progress("cancelled", 0, 0, 0, 0), "id": msg.get("id")}
    worker.task(kind, msg)
    return None


def error_reply(exc: Exception, text: object) -> dict:
    """The `error` answer to the client message `text` that raised `exc`: a ChronoclError's
    own text; anything else is a bug: answered in one line without a traceback, and logged at
    ERROR with its traceback (`errors.error_text`), as a frame's is."""
    message = error_text(exc, "on a message")
    return {"type": "error", "id": request_id(text), "message": message}


def answer(worker: ClientWorker, text: object) -> dict | None:
    """One client message (JSON text) validated and applied; its immediate reply, or the
    `error` reply when it is bad or fails (None: nothing to answer at once)."""
    try:
        return handle(worker, parse_message(text))
    except Exception as exc:
        return error_reply(exc, text)


async def serve_socket(
    websocket,
    datasets: list[Dataset],
    downloads: Downloads,
    *,
    engine: str = "opencl",
    device: str | None = None,
    memory: str | int | None = None,
    shared: SharedSteps | None = None,
) -> None:
    """Serve one accepted-to-be Starlette WebSocket until the client goes (`shared`: the
    server's window managers, which every client's views use)."""
    from starlette.websockets import WebSocketDisconnect

    await websocket.accept()
    loop = asyncio.get_running_loop()
    send_lock = asyncio.Lock()
    gone = threading.Event()

    async def deliver(data: str | bytes) -> None:
        """Send to the client; one that has gone (a closed tab) ends the socket quietly."""
        if gone.is_set():
            return
        async with send_lock:
            try:
                if isinstance(data, bytes):
                    await websocket.send_bytes(data)
                else:
                    await websocket.send_text(data)
            except (WebSocketDisconnect, OSError, RuntimeError):
                # Starlette raises WebSocketDisconnect for a connection that broke, and a
                # RuntimeError (WebSocketDisconnected in Starlette 1) once it saw the close.
                gone.set()

    def send_from_thread(data: str | bytes, wait: bool = True) -> bool:
        """Send from a worker's thread; with `wait` false (a progress note) without waiting
        for the client to take it."""
        if gone.is_set():
            return False
        try:
            sent = asyncio.run_coroutine_threadsafe(deliver(data), loop)
            if wait:
                sent.result(TUNING.send_timeout_s)
        except Exception:  # cancelled, timed out: the client is gone
            gone.set()
        return not gone.is_set()

    worker = ClientWorker(
        datasets,
        send_from_thread,
        downloads,
        engine=engine,
        device=device,
        memory=memory,
        shared=shared,
    )
    steps = None
    try:
        await deliver(json.dumps(info_message(datasets)))
        steps = asyncio.create_task(report_steps(worker.views, deliver, gone))  # the timeline's
        while not gone.is_set():
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                break
            text = message.get("text")
            try:
                if text is None:
                    raise ProtocolError("binary messages are not accepted; send JSON text")
                msg = parse_message(text)
                if msg["type"] == "open":  # reads a sample of the data to fit the data TF
                    reply = await asyncio.to_thread(handle, worker, msg)
                else:
                    reply = handle(worker, msg)
            except Exception as exc:  # answered in one line; a bug logged with its traceback
                reply = error_reply(exc, text)
            if reply is not None:
                await deliver(json.dumps(reply))
    finally:
        gone.set()
        if steps is not None:
            steps.cancel()
        worker.close()
