"""Command-line flags and ``serve`` start-up: every bad value is one line ``error: --flag: what``
and exit 2, never argparse's usage block, a traceback in a thread, or a server that never ends."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DEMO = str(REPO / "sessions" / "demo")


def inspector(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "inspector", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO)


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
    (("report",), "error: inspector report: the following arguments are required: paths"),
    (("report", DEMO, "--no-such-flag"), "unrecognized arguments: --no-such-flag"),
    (("frobnicate",), "invalid choice: 'frobnicate'"),
])
def test_a_bad_flag_is_one_line(args: tuple[str, ...], expected: str) -> None:
    assert_one_line(inspector(*args), expected)


def test_serve_refuses_a_host_that_does_not_resolve_within_seconds() -> None:
    start = time.monotonic()
    out = inspector("serve", "--host", "no.such.host.invalid", "--port", "0", timeout=60)
    assert_one_line(out, "error: --host: cannot resolve 'no.such.host.invalid'")
    assert time.monotonic() - start < 30  # 4 s of resolving at most, plus start-up on a busy machine


def test_serve_refuses_a_port_in_use_within_seconds() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = inspector("serve", "--port", str(port), timeout=60)
    assert_one_line(out, f"error: --port: cannot listen on 127.0.0.1:{port} (")


def test_serve_refuses_an_address_not_on_this_machine() -> None:
    out = inspector("serve", "--host", "192.0.2.1", "--port", "0", timeout=60)  # TEST-NET-1: never local
    assert_one_line(out, "error: --port: cannot listen on 192.0.2.1:0 (")
