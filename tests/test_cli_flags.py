"""Command-line flags and ``serve`` start-up: every bad value is one line ``error: --flag: what``
and exit 2, never argparse's usage block, a traceback in a thread, or a server that never ends."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_processes import CommandServer
from demo_copies import demo_copy

pytestmark = pytest.mark.slow  # the CLI as processes

REPO = Path(__file__).resolve().parents[1]
DEMO = str(REPO / "sessions" / "demo")


@pytest.fixture(scope="module")
def commands():
    """Each refusal is its own process, forked from one that imported the CLI once."""
    with CommandServer() as server:
        yield server


@pytest.fixture
def inspector(commands):
    def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
        return commands.run(*args, timeout=timeout, cwd=REPO)
    return run


def assert_one_line(out: subprocess.CompletedProcess, expected: str) -> None:
    assert out.returncode == 2, out.stderr
    assert out.stdout == ""
    assert out.stderr.count("\n") == 1 and out.stderr.startswith("error: "), out.stderr
    assert expected in out.stderr, out.stderr


@pytest.mark.parametrize(("args", "expected"), [
    (("report", DEMO, "--jobs", "0"), "error: --jobs: must be at least 1 (got 0)"),
    (("report", DEMO, "--jobs", "-3"), "error: --jobs: must be at least 1 (got -3)"),
    (("report", DEMO, "-j", "two"), "error: --jobs: must be a whole number (got 'two')"),
    (("export", DEMO, "--jobs", "0"), "error: --jobs: must be at least 1"),
    (("compare", DEMO, DEMO, "--jobs", "0"), "error: --jobs: must be at least 1"),
    (("report", DEMO, "--limit-margin", "nan"), "error: --limit-margin: must be a finite number (got nan)"),
    (("report", DEMO, "--limit-margin", "inf"), "error: --limit-margin: must be a finite number"),
    (("report", DEMO, "--limit-margin", "-5"), "error: --limit-margin: must be a number of degrees in [0, 360)"),
    (("serve", "--cache-mb", "0"), "error: --cache-mb: must be more than 0 (got 0)"),
    (("serve", "--cache-mb", "-1"), "error: --cache-mb: must be more than 0 (got -1)"),
    (("serve", "--cache-mb", "nan"), "error: --cache-mb: must be a finite number"),
    (("serve", "--port", "70000"), "error: --port: must be a TCP port from 0 to 65535 (got 70000"),
    (("serve", "--port", "-5"), "error: --port: must be a TCP port from 0 to 65535 (got -5"),
    (("export", DEMO, "--episode", "x"), "error: --episode: must be a whole number"),
    (("serve", "--outcome-source", "judge"), "error: --outcome-source: invalid choice: 'judge'"),
    (("export", DEMO, "--outcome-source", "judge"), "error: --outcome-source: invalid choice: 'judge'"),
    (("report",), "error: inspector report: the following arguments are required: paths"),
    (("report", DEMO, "--no-such-flag"), "unrecognized arguments: --no-such-flag"),
    (("frobnicate",), "invalid choice: 'frobnicate'"),
])
def test_a_bad_flag_is_one_line(inspector, args: tuple[str, ...], expected: str) -> None:
    assert_one_line(inspector(*args), expected)


def test_serve_refuses_a_host_that_does_not_resolve_within_seconds(inspector) -> None:
    start = time.monotonic()
    out = inspector("serve", "--host", "no.such.host.invalid", "--port", "0", timeout=60)
    assert_one_line(out, "error: --host: cannot resolve 'no.such.host.invalid'")
    assert time.monotonic() - start < 30  # 4 s of resolving at most, plus start-up on a busy machine


def test_serve_refuses_a_port_in_use_within_seconds(inspector) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = inspector("serve", "--port", str(port), timeout=60)
    assert_one_line(out, f"error: --port: cannot listen on 127.0.0.1:{port} (")


def test_serve_refuses_an_address_not_on_this_machine(inspector) -> None:
    out = inspector("serve", "--host", "192.0.2.1", "--port", "0", timeout=60)  # TEST-NET-1: never local
    assert_one_line(out, "error: --port: cannot listen on 192.0.2.1:0 (")


# Three short rollouts: more tasks than this machine's two cores, in seconds rather than the
# whole demo's minute of exporting.
FEW_ROLLOUTS = ("single_f000", "single_f076", "single_f153")


@pytest.fixture(scope="module")
def few_rollouts(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled demo with only ``FEW_ROLLOUTS`` (read-only for tests)."""
    return demo_copy(tmp_path_factory.mktemp("few"), FEW_ROLLOUTS)


@pytest.mark.parametrize("command", [("report", "{session}", "--json"), ("export", "{session}", "-o", "{out}")])
def test_jobs_past_the_cores_and_tasks_are_capped_in_one_note(tmp_path: Path, few_rollouts: Path,
                                                               command: tuple[str, ...]) -> None:
    """``--jobs 100000`` starts one worker per core (or per task, if fewer), never 100000 idle
    interpreters, and says so in one line; the command's output is as usual."""
    import os
    import re

    import psutil

    args = [a.replace("{out}", str(tmp_path / "out")).replace("{session}", str(few_rollouts)) for a in command]
    with open(tmp_path / "stdout", "w") as stdout:
        proc = subprocess.Popen([sys.executable, "-m", "inspector", *args, "--jobs", "100000", "--no-cache"],
                                stdout=stdout, stderr=subprocess.PIPE, text=True, cwd=REPO)
        parent = psutil.Process(proc.pid)
        workers: set[int] = set()
        while proc.poll() is None:  # sample the process tree while it runs
            try:
                workers |= {c.pid for c in parent.children(recursive=True) if "spawn_main" in " ".join(c.cmdline())}
            except psutil.Error:  # a child ended between listing and reading it
                pass
            time.sleep(0.05)
        stderr = proc.stderr.read() if proc.stderr else ""
    assert proc.returncode == 0, stderr
    cores = len(os.sched_getaffinity(0))
    notes = [line for line in stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1, stderr
    match = re.fullmatch(rf"note: --jobs 100000: using (\d+) workers? \({cores} cores?, (\d+) tasks?\)", notes[0])
    assert match, notes
    used, tasks = int(match[1]), int(match[2])
    assert used == min(cores, tasks)
    assert 0 < len(workers) <= used, (workers, notes)  # spawned workers seen; the resource tracker is not one
