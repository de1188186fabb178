"""Shared pytest fixtures."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# The suite runs on a shared 2-core machine: drawing an example may be slow because the machine
# is, which says nothing about the test. Tests that list their own suppressions add too_slow.
settings.register_profile("shared-machine", suppress_health_check=[HealthCheck.too_slow], deadline=None)
settings.load_profile("shared-machine")

# The repo sits at <work>/main and the shared fixtures at <work>/shared/fixtures.
FIXTURES_DIR = Path(__file__).resolve().parents[2] / "shared" / "fixtures"


@pytest.fixture(autouse=True, scope="session")
def _private_cache_dir(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The metrics and mesh caches of this test run, apart from the user's (and inherited by
    every CLI the tests start)."""
    os.environ["INSPECTOR_CACHE_DIR"] = str(tmp_path_factory.mktemp("inspector-cache"))


@pytest.fixture(scope="session")
def fixtures_dir() -> Path:
    """``../shared/fixtures``; tests using it are skipped when it is absent."""
    if not FIXTURES_DIR.is_dir():
        pytest.skip(f"shared fixtures not found at {FIXTURES_DIR}")
    return FIXTURES_DIR


@pytest.fixture(scope="session")
def dreamzero_dir(fixtures_dir: Path) -> Path:
    """Real DreamZero-SO101 model outputs."""
    return fixtures_dir / "dreamzero_so101"


@pytest.fixture(scope="session")
def imported_session(dreamzero_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every DreamZero-SO101 fixture imported once into a native session (read-only for tests)."""
    from inspector.data.importers.dreamzero_so101 import import_dreamzero

    dest = tmp_path_factory.mktemp("imported") / "dz"
    import_dreamzero(dreamzero_dir, dest, log=lambda _: None)
    return dest


@pytest.fixture(autouse=True)
def _close_pages_left_open(request: pytest.FixtureRequest):
    """Close the pages a test left open in its module's ``browser``: one that fails midway skips
    its own ``page.close()``, and its page keeps drawing software WebGL at full CPU, starving the
    rerun and the tests after it."""
    yield
    browser = getattr(request.node, "funcargs", {}).get("browser")  # only one that was set up
    for context in list(browser.contexts) if browser is not None else []:
        with contextlib.suppress(Exception):  # already closed, or the browser is gone
            context.close()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Real-browser tests may rerun twice: headless Chromium on a busy 2-core machine (software
    WebGL) sometimes misses a timing window that has nothing to do with the app. A test that fails
    three times in a row still fails."""
    if not config.pluginmanager.hasplugin("rerunfailures"):
        return
    for item in items:
        if item.get_closest_marker("browser") is not None:
            item.add_marker(pytest.mark.flaky(reruns=2, reruns_delay=2))
