"""The README is a test: every command of its workflow blocks runs as written, in order, from the
root of a copy of the clone (the README and the demo session: what a fresh clone holds), and the
test command is the one ``.ci/run`` runs.

Three kinds of command cannot run as they are here, and each is run the nearest way that still
checks what it says:

- ``inspector serve ...`` runs until it answers HTTP on a free port (``--port`` added: the
  README's 8080 may be taken), then stops on SIGTERM with exit code 0;
- ``pip install -e ".[X]"`` is not run (the test environment holds every extra; reinstalling would
  point it at the copy): the extra must exist, and what it installs must import;
- ``rerun FILE`` opens Rerun's viewer, which needs a display: the file is checked with
  ``rerun rrd verify`` instead;

and ``inspector eval localhost:8000`` talks to the suite's policy-server stand-in, on a free port.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from tests.test_processes import free_port, wait_until

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
COMMAND_TIMEOUT_S = 600
SERVE_TIMEOUT_S = 180
STOP_TIMEOUT_S = 120
EXTRA_MODULES = {"rerun-sdk": "rerun", "msgpack": "msgpack", "websockets": "websockets", "ray": "ray"}

pytestmark = pytest.mark.slow


def fenced_bash(text: str) -> list[str]:
    """The lines of every ```bash block of ``text``, comments and blank lines dropped."""
    lines: list[str] = []
    for block in re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M):
        for line in block.splitlines():
            line = re.sub(r"\s+#\s.*$", "", line).strip()
            if line and not line.startswith("#"):
                lines.append(line)
    return lines


def section(text: str, heading: str) -> str:
    """``text`` from the ``## heading`` line to the next ``## `` heading."""
    start = text.index(f"\n## {heading}\n")
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else len(text)]


def workflow_commands() -> list[str]:
    return fenced_bash(section((REPO / "README.md").read_text(encoding="utf-8"), "Workflows"))


def test_the_workflows_are_found_and_name_only_what_the_clone_or_an_earlier_command_has() -> None:
    commands = workflow_commands()
    assert commands[0] == "inspector demo --checkpoints", commands[:1]
    assert len(commands) >= 15
    for gone in ("gpu-host", "IDM_dump", "dreams/", "/shared/", "~/.cache", "me/so101_pick"):
        assert not any(gone in c for c in commands), gone


def test_ci_runs_the_readmes_test_command() -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    marker = readme.index("<!-- the test command")
    test_command = fenced_bash(readme[marker:])[0]
    assert test_command.endswith("python -m pytest -q") and "torch==" in test_command
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert "<!-- the test command" in ci and 'eval "${test_command%"$tests"}"' in ci and 'eval "${tests# && }"' in ci


def extras() -> dict[str, list[str]]:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]


def test_the_first_command_installs_no_test_tool_torch_ray_or_rerun() -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    setup = fenced_bash(readme[:readme.index("## What it does")])[0]
    assert "pip install -e . &&" in setup and setup.endswith("inspector serve"), setup
    base = " ".join(tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"])
    for heavy in ("torch", "ray", "playwright", "pytest", "rerun-sdk"):
        assert heavy not in base, heavy


@pytest.fixture(scope="module")
def clone(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """What a fresh clone holds that the workflows read: the README and the demo session."""
    root = tmp_path_factory.mktemp("clone")
    shutil.copy(REPO / "README.md", root / "README.md")
    shutil.copytree(REPO / "sessions" / "demo", root / "sessions" / "demo")
    return root


def run_env() -> dict[str, str]:
    return {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}", "RAY_USAGE_STATS_ENABLED": "0"}


def check_extra(command: str) -> None:
    name = re.fullmatch(r'pip install -e "\.\[(\w+)\]"', command)
    assert name, f"a pip line the test does not know: {command}"
    requirements = extras()[name.group(1)]
    for requirement in requirements:
        package = re.split(r"[<>=\[ ]", requirement, maxsplit=1)[0]
        module = EXTRA_MODULES.get(package, package.replace("-", "_"))
        assert importlib.util.find_spec(module) is not None, f"{command}: {module} does not import"


@contextmanager
def stand_in_policy_server() -> Iterator[int]:
    from tests.policy_server import policy_server

    with policy_server() as server:
        yield server.port


def serve_until_it_answers(command: str, cwd: Path) -> None:
    port = free_port()
    proc = subprocess.Popen(f"{command} --port {port}", shell=True, cwd=cwd, env=run_env(), start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def answers() -> bool:
        assert proc.poll() is None, f"{command}: ended with {proc.returncode}:\n{proc.stdout.read() if proc.stdout else ''}"
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}", timeout=5) as reply:
                return reply.status == 200
        except OSError:
            return False

    try:
        wait_until(answers, SERVE_TIMEOUT_S, f"{command} to answer on port {port}")
    finally:
        os.killpg(proc.pid, signal.SIGTERM)  # the shell and the server it started
        try:
            out, _ = proc.communicate(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
            raise AssertionError(f"{command}: still running {STOP_TIMEOUT_S} s after SIGTERM:\n{out}") from None
    # 0: stopped serving; 143: stopped while still starting (the CLI's exit code for SIGTERM)
    assert proc.returncode in (0, 128 + signal.SIGTERM, -signal.SIGTERM), f"{command}: exit {proc.returncode}\n{out}"


def run_command(command: str, cwd: Path) -> None:
    if command.startswith("pip install"):
        check_extra(command)
        return
    if command.startswith("inspector serve"):
        serve_until_it_answers(command, cwd)
        return
    if command.startswith("rerun "):
        command = f"rerun rrd verify {command.removeprefix('rerun ')}"
    if "localhost:8000" in command:
        with stand_in_policy_server() as port:
            done = subprocess.run(command.replace("localhost:8000", f"127.0.0.1:{port}"), shell=True, cwd=cwd,
                                  env=run_env(), capture_output=True, text=True, timeout=COMMAND_TIMEOUT_S)
    else:
        done = subprocess.run(command, shell=True, cwd=cwd, env=run_env(), capture_output=True, text=True,
                              timeout=COMMAND_TIMEOUT_S)
    assert done.returncode == 0, f"{command}: exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}"
    assert "Traceback" not in done.stderr, f"{command}:\n{done.stderr[-2000:]}"


def test_every_workflow_command_runs_as_written(clone: Path) -> None:
    ran: list[tuple[str, float]] = []
    for command in workflow_commands():
        started = time.monotonic()
        run_command(command, clone)
        ran.append((command, time.monotonic() - started))
    # what the commands were to leave behind, as the README says
    assert {p.name for p in (clone / "sessions").iterdir()} >= {"demo", "served-eval", "step-56000", "step-64000",
                                                              "step-72000"}
    assert (clone / "report.html").stat().st_size > 0 and (clone / "ep1.rrd").stat().st_size > 0
    assert (clone / "share" / "limits_wrist.rrd").is_file()
    assert b'"rollouts"' in (clone / "report.json").read_bytes()
    imported = (clone / "sessions" / "step-72000" / "outcomes.json").read_text(encoding="utf-8")
    assert '"file"' in imported and "judge.jsonl" in imported
    print("\n".join(f"{seconds:6.1f} s  {command}" for command, seconds in ran))
