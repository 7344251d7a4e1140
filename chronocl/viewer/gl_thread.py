"""The viewer's one GL thread, which owns its EGL context and raycaster.

A context can be current in only one thread, and the process's own context may already be
current in another, so all of the viewer's GL work (uploads, draws, releases) is handed to
this thread by `on_gl`.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

_gl_executor: ThreadPoolExecutor | None = None
_gl_raycaster = None
_gl_guard = threading.Lock()
_gl_ident: int | None = None  # the GL thread's, once it ran something


def on_gl(fn: Callable, *args):
    """fn(raycaster, *args) on the viewer's GL thread; returns its result (or raises). Called
    on that thread (a recoloured chronovolume read there reads its texture), it runs at once:
    waiting for the thread's own queue would wait for ever."""
    if threading.get_ident() == _gl_ident:
        return _on_gl(fn, args)
    return gl_submit(fn, *args).result()


def gl_submit(fn: Callable, *args) -> Future:
    """fn(raycaster, *args) queued on the viewer's GL thread, without waiting: the thread runs
    what is queued in order, so a later `on_gl` runs after it."""
    global _gl_executor
    with _gl_guard:
        if _gl_executor is None:
            _gl_executor = ThreadPoolExecutor(1, thread_name_prefix="chronocl-viewer-gl")
    return _gl_executor.submit(_on_gl, fn, args)


def release_on_gl(fn: Callable, *args) -> None:
    """fn(raycaster, *args) on the GL thread to free GL objects, waited for; nothing where that
    thread takes no more work: the interpreter is exiting (a client's thread still releasing
    its views then), and the context goes with the process, all it holds included."""
    try:
        done = gl_submit(fn, *args)
    except RuntimeError:  # ThreadPoolExecutor.submit after the interpreter's shutdown began
        return
    done.result()


def _on_gl(fn: Callable, args: tuple):
    global _gl_raycaster, _gl_ident
    _gl_ident = threading.get_ident()
    if _gl_raycaster is None:
        from chronocl.render.gl import new_egl_context
        from chronocl.render.raycaster import Raycaster

        _gl_raycaster = Raycaster(new_egl_context())
    return fn(_gl_raycaster, *args)
