"""Shared pytest fixtures."""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import pytest
import worker_groups
from hypothesis import HealthCheck, settings

# The suite runs on a shared 2-core machine: drawing an example may be slow because the machine
# is, which says nothing about the test. Tests that list their own suppressions add too_slow.
settings.register_profile("shared-machine", suppress_health_check=[HealthCheck.too_slow], deadline=None)
settings.load_profile("shared-machine")

REPO = Path(__file__).resolve().parents[1]
# What the repository owns: LeRobot-written datasets (tests/data/lerobot/README.md) and the demo.
LEROBOT_DATA = REPO / "tests" / "data" / "lerobot"
DEMO_SESSION = REPO / "sessions" / "demo"
# The real DreamZero-SO101 outputs are not ours to redistribute: the folder holding
# ``dreamzero_so101/`` is named by this variable (default: the shared fixtures beside the repo).
FIXTURES_ENV = "INSPECTOR_FIXTURES"


def real_fixtures_dir() -> Path:
    """The folder that holds ``dreamzero_so101/`` (``$INSPECTOR_FIXTURES``, else ``<repo>/../shared/fixtures``)."""
    value = os.environ.get(FIXTURES_ENV)
    return Path(value).expanduser() if value else REPO.parent / "shared" / "fixtures"


def real_outputs_skip_reason() -> str | None:
    """Why the tests of the real DreamZero-SO101 outputs cannot run here (None: they can)."""
    where = real_fixtures_dir() / "dreamzero_so101"
    if where.is_dir():
        return None
    return (f"real DreamZero-SO101 outputs not found at {where}: set {FIXTURES_ENV} to the folder "
            f"holding dreamzero_so101/")


@pytest.fixture(autouse=True, scope="session")
def _private_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The metrics and mesh caches of this test run, apart from the user's, inherited by every
    CLI the tests start. One for the run's workers together (in the run's own temporary folder,
    above each worker's): a rollout that several modules report, the demo's above all, is computed
    once a run, as a user's second report reads the first one's rows (entries are written whole,
    by rename, so workers may share them). Tests of the cache itself use caches of their own."""
    run_dir = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        run_dir = run_dir.parent  # (each worker's folder is under the run's)
    cache = run_dir / "inspector-cache"
    cache.mkdir(exist_ok=True)
    os.environ["INSPECTOR_CACHE_DIR"] = str(cache)


# How long the processes the tests started get to end after the last test [s] (generous: a busy
# 2-core machine; the guarantee itself is a few seconds).
LEFTOVER_TIMEOUT_S = 60.0


@pytest.fixture(autouse=True, scope="session")
def _no_process_left_behind():
    """Every process the tests start (commands, their workers, servers, browsers) has ended once
    the tests have: a process left running, e.g. a worker that outlived its command, fails the run,
    listing what is left. multiprocessing's resource tracker aside: it lives as long as this
    process does, by design.

    On Linux this process adopts the orphans of the processes it starts (a child subreaper), so a
    worker left behind by a command a test ran, whose parent has ended, is still found here
    rather than under init. Elsewhere only this process's own descendants are checked.
    """
    _adopt_orphans()
    yield
    import psutil

    def leftovers() -> dict[int, str]:
        left = {}
        for p in psutil.Process().children(recursive=True):
            try:
                if p.status() == psutil.STATUS_ZOMBIE:
                    continue  # ended; only its exit status is left to collect
                cmdline = " ".join(p.cmdline())
            except psutil.Error:
                continue  # ended meanwhile
            if "multiprocessing.resource_tracker" not in cmdline:
                left[p.pid] = cmdline
        return left

    deadline = time.monotonic() + LEFTOVER_TIMEOUT_S
    while (left := leftovers()) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not left, "processes the tests left running:\n" + "\n".join(f"  {pid}: {cmd}" for pid, cmd in left.items())


def _adopt_orphans() -> bool:
    """Linux: become the child subreaper of every process started from here on (prctl
    PR_SET_CHILD_SUBREAPER); False where that is not available."""
    import ctypes

    PR_SET_CHILD_SUBREAPER = 36
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):  # not Linux
        return False


@pytest.fixture(scope="session")
def lerobot_dir() -> Path:
    """``tests/data/lerobot``: the SO-101 datasets LeRobot's own writer made (v3.0 and v2.1)."""
    return LEROBOT_DATA


@pytest.fixture(scope="session")
def dreamzero_dir() -> Path:
    """Real DreamZero-SO101 model outputs (``$INSPECTOR_FIXTURES/dreamzero_so101``); tests using
    them are skipped when absent."""
    reason = real_outputs_skip_reason()
    if reason is not None:
        pytest.skip(reason)
    return real_fixtures_dir() / "dreamzero_so101"


@pytest.fixture(scope="session")
def imported_session(dreamzero_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every real DreamZero-SO101 output imported once into a native session (read-only for tests)."""
    from inspector.data.importers.dreamzero_so101 import import_dreamzero

    dest = tmp_path_factory.mktemp("imported") / "dz"
    import_dreamzero(dreamzero_dir, dest, log=lambda _: None)
    return dest


@pytest.fixture(scope="session")
def dz_layout(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A source directory in the DreamZero-SO101 layout made from the bundled demo, written once
    (read-only for tests; ``dreamzero_layout.py`` says what it holds)."""
    from dreamzero_layout import write_dreamzero_layout

    return write_dreamzero_layout(tmp_path_factory.mktemp("dz-layout") / "dreamzero_so101")


@pytest.fixture(scope="session")
def dz_layout_session(dz_layout: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``dz_layout`` imported once into a native session (read-only for tests)."""
    from inspector.data.importers.dreamzero_so101 import import_dreamzero

    return import_dreamzero(dz_layout, tmp_path_factory.mktemp("dz-layout-session") / "dz", log=lambda _: None)


@pytest.fixture(scope="session")
def playwright():
    """Playwright, started once for the whole run: its sync API allows one instance per thread, so
    a test that needs a browser of its own launches it from this one (``browser.launch``)."""
    from browser import skip_reason

    if (reason := skip_reason()) is not None:
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        yield p


@pytest.fixture(scope="session")
def browser(playwright):
    """One headless Debian Chromium for the whole run (launching one costs seconds, and its first
    page compiles the app's scripts): every test opens its own pages, each in a fresh context
    (``browser.open_page``), and closes them; ``_close_pages_left_open`` closes what a failed test left."""
    from browser import launch

    b = launch(playwright)
    yield b
    b.close()


@pytest.fixture(scope="session")
def demo_app():
    """The bundled demo served once for the whole run, for tests that only read it (each in pages
    of its own): its Overview rows are computed once, its playback clips encoded once."""
    from inspector.app import serve
    from inspector.data.sources import BUNDLED_DEMO

    app = serve([BUNDLED_DEMO], port=0, block=False)
    yield app
    app.stop()


@pytest.fixture(autouse=True)
def _close_pages_left_open(request: pytest.FixtureRequest):
    """Close the pages a test left open in the shared ``browser``: one that fails midway skips
    its own ``page.close()``, and its page keeps drawing software WebGL at full CPU, starving the
    rerun and the tests after it."""
    yield
    browser = (getattr(request.node, "funcargs", None) or {}).get("browser")  # only one that was set up
    for context in list(browser.contexts) if browser is not None else []:
        with contextlib.suppress(Exception):  # already closed, or the browser is gone
            context.close()


# A test that asks for one of these drives a real browser: it is marked ``browser`` and ``slow``
# wherever it is (a page takes seconds to load on a 2-core machine), so ``-m "not slow"`` leaves it out.
BROWSER_FIXTURES = frozenset({"browser", "playwright"})


def pytest_configure(config: pytest.Config) -> None:
    _compile_once_a_run(config)
    worker_groups.configure(config)


def _compile_once_a_run(config: pytest.Config) -> None:
    """Where the environment says to write no bytecode (``PYTHONDONTWRITEBYTECODE``), every
    process a run starts (the xdist workers, commands, report workers) compiled each module it
    imported from source again, and each worker rewrote every test module's asserts again. The run
    keeps compiled files in a folder of its own instead (``PYTHONPYCACHEPREFIX``), never in the
    checkout, so each module is compiled once a run. Set here, before the workers start: they and
    what they start inherit it."""
    if not os.environ.get("PYTHONDONTWRITEBYTECODE") or hasattr(config, "workerinput"):
        return
    prefix = tempfile.mkdtemp(prefix="inspector-test-pycache-")
    del os.environ["PYTHONDONTWRITEBYTECODE"]
    os.environ["PYTHONPYCACHEPREFIX"] = prefix
    sys.dont_write_bytecode, sys.pycache_prefix = False, prefix
    config.add_cleanup(lambda: shutil.rmtree(prefix, ignore_errors=True))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """``--dist loadgroup`` (pyproject.toml's addopts) as ``worker_groups`` defines the groups."""
    return worker_groups.make_scheduler(config, log) if config.getvalue("dist") == "loadgroup" else None


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects by these marks; before xdist reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests that use the shared browser (``BROWSER_FIXTURES``) ``browser`` and ``slow``.

    Real-browser tests may rerun twice: headless Chromium on a busy 2-core machine (software
    WebGL) sometimes misses a timing window that has nothing to do with the app. A test that fails
    three times in a row still fails."""
    for item in items:
        if BROWSER_FIXTURES & set(getattr(item, "fixturenames", ())):
            for mark in ("browser", "slow"):
                if item.get_closest_marker(mark) is None:
                    item.add_marker(getattr(pytest.mark, mark))
    worker_groups.record(config, items)
    if not config.pluginmanager.hasplugin("rerunfailures"):
        return
    for item in items:
        if item.get_closest_marker("browser") is not None:
            item.add_marker(pytest.mark.flaky(reruns=2, reruns_delay=2))
