"""`python -m chronocl ARGS` for the tests, without paying its imports each time.

A fresh `python -m chronocl` spends about 2 s here importing numpy, zarr, dask and pyopencl
before it parses its first option, and the suite runs hundreds of them. `run` asks a server
process (`python -m tests.cli_process`, one per test process, started on first use) that
imported `chronocl.cli` once and forks a child per command. The child takes the caller's
environment, folder and an empty stdin, runs `chronocl` as `python -m chronocl` does (runpy:
the same `sys.argv` and usage lines) and exits as the interpreter would: its exit code,
threads joined, atexit handlers run, output flushed. Only the teardown of every module is
left out (0.4 s of garbage collection a command, which nothing a command leaves may rely on:
a file left open unflushed would lose its tail here, but is a bug there too). Nothing has run
in the server before the fork but imports, so each command starts as fresh as in a process
of its own. Commands run in a process of their own instead where the imports printed anything
(a warning every real process would print), where the caller's environment differs from the
server's in what imports may read (`IMPORT_TIME`), where the folder is missing, and
everywhere with CHRONOCL_CLI_SUBPROCESS=1.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Variables that imports may read (a fork cannot take them back): commands setting them
# differently from the server run in a process of their own.
IMPORT_TIME = (
    *("CHRONOCL_", "POCL_", "PYOPENCL_", "PYTHON", "XDG_", "HOME", "TMPDIR", "DASK_", "ZARR_"),
    *("OMP_", "OPENBLAS_", "MKL_", "NUMPY_", "NPY_", "LANG", "LC_"),
    *("COLUMNS", "LINES", "TERM", "NO_COLOR", "FORCE_COLOR", "TTY_"),  # rich's consoles
)
SET_BY_IMPORTS = {"PYOPENCL_HOME"}  # pyopencl's import sets it to where it lies


def run(
    argv: list[str], cwd=None, timeout: float = 120, own_process: bool = False
) -> subprocess.CompletedProcess:
    """`python -m chronocl *argv` in `cwd`, its output captured as text, as `subprocess.run`
    returns it (TimeoutExpired past `timeout`); `own_process`: in a fresh process always."""
    argv = [str(a) for a in argv]
    env = dict(os.environ)
    cwd = str(cwd or os.getcwd())
    server = None
    if not own_process and os.environ.get("CHRONOCL_CLI_SUBPROCESS") != "1" and os.path.isdir(cwd):
        server = _server()
    if server is None or server.differs(env):
        return subprocess.run(
            [sys.executable, "-m", "chronocl", *argv],
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=timeout,
        )
    return server.run(argv, cwd, env, timeout)


class _Server:
    def __init__(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.cli_process"],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        self.lock = threading.Lock()
        self.scratch = os.path.join(
            os.environ.get("CHRONOCL_TEST_CACHE") or "/tmp", f"cli-{os.getpid()}"
        )
        os.makedirs(self.scratch, exist_ok=True)
        self.count = 0
        self.pending = b""
        self.dead = False
        started = json.loads(self._line(120))  # the server's environment after its imports
        self.env = started["env"]
        # what the imports printed would be printed by every real process: none may use it
        self.usable = not started["said"]

    def differs(self, env: dict) -> bool:
        if not self.usable:
            return True
        keys = {k for k in (*env, *self.env) if k.startswith(IMPORT_TIME)} - SET_BY_IMPORTS
        return any(env.get(k) != self.env.get(k) for k in keys)

    def run(self, argv, cwd, env, timeout) -> subprocess.CompletedProcess:
        with self.lock:  # one command at a time
            self.count += 1
            out = os.path.join(self.scratch, f"{self.count}.out")
            err = os.path.join(self.scratch, f"{self.count}.err")
            pid = None
            try:
                request = {"argv": argv, "cwd": cwd, "env": env, "out": out, "err": err}
                self.proc.stdin.write(json.dumps(request).encode() + b"\n")
                self.proc.stdin.flush()
                pid = int(self._line(30))
                code = int(self._line(timeout))
                texts = []
                for path in (out, err):
                    with open(path) as f:  # decoded as `subprocess.run(text=True)` decodes
                        texts.append(f.read())
            except BaseException as exc:
                self._stop(pid)  # out of step with it: the next command gets a new one
                if isinstance(exc, subprocess.TimeoutExpired):
                    raise subprocess.TimeoutExpired(["chronocl", *argv], timeout) from None
                raise
            finally:
                for path in (out, err):
                    if os.path.exists(path):
                        os.unlink(path)
        return subprocess.CompletedProcess(["chronocl", *argv], code, *texts)

    def _line(self, timeout: float) -> str:
        """The server's next line (its own buffer: a select on the pipe sees no line that an
        earlier read took in already)."""
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while b"\n" not in self.pending:
            ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
            if not ready:
                raise subprocess.TimeoutExpired("chronocl", timeout)
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                raise RuntimeError("the CLI server of the tests died")
            self.pending += chunk
        line, self.pending = self.pending.split(b"\n", 1)
        return line.decode()

    def _stop(self, pid: int | None) -> None:
        self.dead = True
        for victim in (pid, self.proc.pid):
            if victim is not None:
                try:
                    os.kill(victim, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        self.proc.wait()


_SERVER: _Server | None = None
_STARTING = threading.Lock()


def _server() -> _Server | None:
    global _SERVER
    with _STARTING:
        if _SERVER is None or _SERVER.dead or _SERVER.proc.poll() is not None:
            _SERVER = _Server()
        return _SERVER


def _child(request: dict) -> None:
    """Run one command as `python -m chronocl` would, then exit as the interpreter does."""
    import atexit
    import runpy
    import traceback

    code = 1
    try:
        os.environ.clear()
        os.environ.update(request["env"])
        os.chdir(request["cwd"])
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.close(null)
        for fd, name in ((1, "out"), (2, "err")):
            target = os.open(request[name], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(target, fd)
            os.close(target)
        sys.stdin = open(os.devnull)  # the process's stdin until it exits
        sys.argv = ["chronocl", *request["argv"]]
        interrupted = False
        try:
            runpy.run_module("chronocl", run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as exc:  # as the interpreter reads it
            if isinstance(exc.code, int) or exc.code is None:
                code = exc.code or 0
            else:
                print(exc.code, file=sys.stderr)
        except KeyboardInterrupt:  # the interpreter: the traceback, then killed by SIGINT
            traceback.print_exc()
            interrupted = True
        except BaseException:  # the interpreter: the traceback, exit 1
            traceback.print_exc()
        # the interpreter's exit, up to its teardown of every module
        threading._shutdown()
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
        if interrupted:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGINT)
    finally:
        os._exit(code)


def _serve() -> None:
    # what the imports print (a warning) goes to a file: the client is told, and runs every
    # command in a process of its own then
    said = os.path.join(os.environ.get("CHRONOCL_TEST_CACHE") or "/tmp", f"said-{os.getpid()}")
    saved = os.dup(2)
    with open(said, "w") as f:
        os.dup2(f.fileno(), 2)
        import chronocl.cli  # noqa: F401 - the imports every command would pay, paid once

        sys.stderr.flush()
        os.dup2(saved, 2)
    with open(said) as f:
        text = f.read()
    os.unlink(said)
    print(json.dumps({"env": dict(os.environ), "said": text}), flush=True)
    pending = b""
    while True:
        while b"\n" not in pending:
            chunk = os.read(0, 1 << 16)
            if not chunk:
                return
            pending += chunk
        line, pending = pending.split(b"\n", 1)
        request = json.loads(line)
        pid = os.fork()
        if pid == 0:
            _child(request)  # never returns
        print(pid, flush=True)
        _, status = os.waitpid(pid, 0)
        print(os.waitstatus_to_exitcode(status), flush=True)


if __name__ == "__main__":
    _serve()
