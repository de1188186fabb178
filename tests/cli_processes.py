"""``inspector`` commands as real processes that share one start-up.

``python -m inspector`` pays its imports (Python, numpy, the CLI and what the command loads) in
every process: on a busy 2-core machine that is a second or more per command, which dominates a
module that runs dozens of one-line refusals. ``CommandServer`` starts one Python process that
imports the CLI once and forks a child per command: each child is a separate process, with its own
working directory, environment, stdout and stderr files and exit status, that runs ``main`` and
exits as ``python -m inspector`` would (an uncaught exception prints its traceback and exits 1).

Use it where the point is a command's output and exit code; keep ``subprocess`` for what a
forked child would not show the same way (start-up itself, peak memory, signals).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import pytest

# The forking process: read one JSON request a line, fork a child that runs it, answer the
# child's exit status. Children are reaped before the next request (one command at a time per
# server; a test that wants several at once starts several servers).
_SERVER = r"""
import importlib, json, os, sys, tempfile, traceback
import numpy  # noqa: F401  (what every command loads: paid once here)
from inspector.cli import build_parser, main
build_parser()  # (and the modules it reads defaults from)

# What a command that reads rollouts or datasets imports (a second of CPU): imported here before
# the first such command forks, and never for a module whose commands only refuse. Imports only:
# no thread or pool is started before a fork.
COMPUTING = {"report", "compare", "export", "import", "info"}
ROW_MODULES = ("av", "pyarrow.parquet", "pyarrow.dataset", "pyarrow.compute",
               "inspector.report.build", "inspector.rows.tasks", "inspector.analysis.sweep",
               "inspector.analysis.video_metrics", "inspector.analysis.video_break",
               "inspector.robot.kinematics", "inspector.data.sources", "concurrent.futures.process")
preloaded = False

def serve():
    global preloaded
    for line in sys.stdin:
        req = json.loads(line)
        if not preloaded and req["argv"][:1] and req["argv"][0] in COMPUTING:
            for name in ROW_MODULES:
                importlib.import_module(name)
            preloaded = True
        pid = os.fork()
        if pid == 0:
            return req
        print(pid, flush=True)
        _, status = os.waitpid(pid, 0)
        print(os.waitstatus_to_exitcode(status), flush=True)
    return None

req = serve()
if req is None:
    sys.exit(0)
# The child: become the command.
sys.stdin.close()
os.chdir(req["cwd"])
os.environ.clear()
os.environ.update(req["env"])
tempfile.tempdir = None  # (TMPDIR is read anew)
for fd, path in ((1, req["stdout"]), (2, req["stderr"])):
    f = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.dup2(f, fd)
    os.close(f)
sys.stdout = open(1, "w", encoding="utf-8", errors="backslashreplace", closefd=False, buffering=1)
sys.stderr = open(2, "w", encoding="utf-8", errors="backslashreplace", closefd=False, buffering=1)
sys.argv = ["inspector", *req["argv"]]
sys.exit(main(req["argv"]))
"""


class CommandServer:
    """One forking process; ``run`` is ``subprocess.run([python, -m, inspector, *argv])``."""

    def __init__(self) -> None:
        self._proc = subprocess.Popen([sys.executable, "-c", _SERVER], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, text=True, cwd=Path(__file__).resolve().parents[1])
        self._lock = threading.Lock()
        self._dir = tempfile.TemporaryDirectory(prefix="inspector-commands-")
        self._n = 0

    def run(self, *argv: object, cwd: Path | str | None = None, env: dict[str, str] | None = None,
            timeout: float = 300) -> subprocess.CompletedProcess:
        """Run ``inspector ARGV`` in a forked child; its exit status, stdout and stderr (the child
        is killed after ``timeout`` seconds: ``subprocess.TimeoutExpired``)."""
        args = [str(a) for a in argv]
        with self._lock:
            self._n += 1
            out, err = (Path(self._dir.name) / f"{self._n}.{name}" for name in ("out", "err"))
            request = {"argv": args, "cwd": str(cwd or os.getcwd()), "env": dict(os.environ if env is None else env),
                       "stdout": str(out), "stderr": str(err)}
            assert self._proc.stdin is not None and self._proc.stdout is not None
            self._proc.stdin.write(json.dumps(request) + "\n")
            self._proc.stdin.flush()
            pid = int(self._read())
            killed = threading.Event()

            def kill() -> None:
                killed.set()
                os.kill(pid, signal.SIGKILL)

            timer = threading.Timer(timeout, kill)
            timer.start()
            try:
                code = int(self._read())
            finally:
                timer.cancel()
            if killed.is_set():
                raise subprocess.TimeoutExpired(["inspector", *args], timeout)
        result = subprocess.CompletedProcess(["inspector", *args], code, out.read_text(errors="replace"),
                                             err.read_text(errors="replace"))
        out.unlink()
        err.unlink()
        return result

    def _read(self) -> str:
        assert self._proc.stdout is not None
        answer = self._proc.stdout.readline()
        if not answer:
            raise RuntimeError(f"the command server ended (exit {self._proc.poll()})")
        return answer

    def close(self) -> None:
        assert self._proc.stdin is not None
        self._proc.stdin.close()
        self._proc.wait(60)
        self._dir.cleanup()

    def __enter__(self) -> CommandServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def module_command_server():
    """A test module's own :class:`CommandServer`: ``(fixture, run)``. Assign the fixture to a name
    in the module (an autouse, module-scoped fixture: the server lives while the module's tests
    run) and call ``run(*argv, **kwargs)`` as :meth:`CommandServer.run`."""
    servers: list[CommandServer] = []

    @pytest.fixture(scope="module", autouse=True, name="_command_server")
    def fixture():
        with CommandServer() as server:
            servers.append(server)
            yield server
            servers.clear()

    def run(*argv: object, **kwargs) -> subprocess.CompletedProcess:
        return servers[0].run(*argv, **kwargs)

    return fixture, run
