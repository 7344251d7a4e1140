"""`python -m chronocl ARGS` for the tests, without paying its imports each time.

A fresh `python -m chronocl` spends about 2 s here importing numpy, zarr, dask and pyopencl
before it parses its first option, and the suite runs hundreds of them. `run` asks a server
process (`python -m tests.cli_process`, one per test process, started on first use) that
imported `chronocl.cli` once and forks a child per command. The child takes the caller's
environment, folder and an empty stdin, runs `chronocl` as `python -m chronocl` does (runpy:
the same `sys.argv` and usage lines) and exits as the interpreter would: its exit code,
threads joined, atexit handlers run, output flushed. Only the teardown of every module is
left out (0.4 s of garbage collection a command, which nothing a command leaves may rely on).
Nothing has run in the server before the fork but imports, so each command starts as fresh
as in a process of its own. A command whose environment differs from the server's in what
imports may read (chronocl's, PoCL's, pyopencl's and Python's own variables) runs in a
process of its own instead, as does every command where CHRONOCL_CLI_SUBPROCESS=1.
"""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import threading

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Variables that imports may read (a fork cannot take them back): commands setting them
# differently from the server run in a process of their own.
IMPORT_TIME = ("CHRONOCL_", "POCL_", "PYOPENCL_", "PYTHON", "XDG_", "OMP_", "DASK_", "HOME")
SET_BY_IMPORTS = {"PYOPENCL_HOME"}  # pyopencl's import sets it to where it lies


def run(argv: list[str], cwd=None, timeout: float = 120) -> subprocess.CompletedProcess:
    """`python -m chronocl *argv` in `cwd`, its output captured as text, as `subprocess.run`
    returns it (TimeoutExpired past `timeout`)."""
    argv = [str(a) for a in argv]
    env = dict(os.environ)
    server = _server()
    if os.environ.get("CHRONOCL_CLI_SUBPROCESS") == "1" or server is None or server.differs(env):
        return subprocess.run(
            [sys.executable, "-m", "chronocl", *argv],
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=timeout,
        )
    return server.run(argv, str(cwd or os.getcwd()), env, timeout)


class _Server:
    def __init__(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.cli_process"],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.lock = threading.Lock()
        self.scratch = os.path.join(
            os.environ.get("CHRONOCL_TEST_CACHE") or "/tmp", f"cli-{os.getpid()}"
        )
        os.makedirs(self.scratch, exist_ok=True)
        self.count = 0
        self.env = json.loads(self._line(120))  # the server's, after its imports

    def differs(self, env: dict) -> bool:
        keys = {k for k in (*env, *self.env) if k.startswith(IMPORT_TIME)} - SET_BY_IMPORTS
        return any(env.get(k) != self.env.get(k) for k in keys)

    def run(self, argv, cwd, env, timeout) -> subprocess.CompletedProcess:
        with self.lock:  # one command at a time through the pipe; the forks run apart
            self.count += 1
            out = os.path.join(self.scratch, f"{self.count}.out")
            err = os.path.join(self.scratch, f"{self.count}.err")
            request = {"argv": argv, "cwd": cwd, "env": env, "out": out, "err": err}
            self.proc.stdin.write(json.dumps(request) + "\n")
            self.proc.stdin.flush()
            pid = int(self._line(10))
            try:
                code = int(self._line(timeout))
            except subprocess.TimeoutExpired:
                os.kill(pid, 9)
                self._line(10)
                raise subprocess.TimeoutExpired(["chronocl", *argv], timeout) from None
        texts = []
        for path in (out, err):
            with open(path, errors="replace") as f:
                texts.append(f.read())
            os.unlink(path)
        return subprocess.CompletedProcess(["chronocl", *argv], code, *texts)

    def _line(self, timeout: float) -> str:
        ready, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not ready:
            raise subprocess.TimeoutExpired("chronocl", timeout)
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the CLI server of the tests died")
        return line


_SERVER: _Server | None = None
_STARTING = threading.Lock()


def _server() -> _Server | None:
    global _SERVER
    with _STARTING:
        if _SERVER is None or _SERVER.proc.poll() is not None:
            _SERVER = _Server()
        return _SERVER


def _child(request: dict) -> None:
    """Run one command as `python -m chronocl` would, then exit as the interpreter does."""
    import atexit
    import runpy
    import traceback

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
    code = 0
    try:
        runpy.run_module("chronocl", run_name="__main__", alter_sys=True)
    except SystemExit as exc:  # as the interpreter reads it
        if isinstance(exc.code, int) or exc.code is None:
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    except BaseException:  # as the interpreter would: the traceback, exit 1
        traceback.print_exc()
        code = 1
    # the interpreter's exit, up to its teardown of every module
    threading._shutdown()
    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _serve() -> None:
    import chronocl.cli  # noqa: F401 - the imports every command would pay, paid once

    print(json.dumps(dict(os.environ)), flush=True)  # as the imports left it (pyopencl's own)
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
