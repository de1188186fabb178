"""Which tests a pytest-xdist worker runs together (``-n 2``, the addopts in pyproject.toml).

Every browser test goes to one worker, one after another: a page draws WebGL in software, and two
pages drawing at once on a 2-core machine starve each other past their deadlines. The other tests
go by module, so that a module's fixtures (a served app, a batch of CLI runs) are made once.

pytest-xdist's own ``--dist loadgroup`` reads ``xdist_group`` marks by renaming each test's node
id, which pytest 9.2 no longer allows; so the groups travel another way: each worker writes the
group of every test it collected to a file in a folder the controller made, and the controller's
scheduler reads them when it splits the run into work units (all workers have collected by then).
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import pytest

GROUPS_DIR_ENV = "INSPECTOR_TEST_GROUPS_DIR"
BROWSER_GROUP = "browser"


def group_of(item: pytest.Item) -> str:
    """The work unit ``item`` belongs to: the browser group, or its module."""
    if item.get_closest_marker("browser") is not None:
        return BROWSER_GROUP
    return item.nodeid.split("::", 1)[0]


def is_controller(config: pytest.Config) -> bool:
    """True in the process that schedules workers (``-n N`` with N > 0), not in a worker."""
    return not hasattr(config, "workerinput") and bool(getattr(config.option, "numprocesses", 0))


def configure(config: pytest.Config) -> None:
    """Controller: make the folder the workers write their groups to (they inherit the variable)."""
    if is_controller(config):
        folder = tempfile.mkdtemp(prefix="inspector-test-groups-")
        os.environ[GROUPS_DIR_ENV] = folder
        config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))


def record(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Worker: write the group of every collected test for the controller."""
    worker = getattr(config, "workerinput", {}).get("workerid")
    folder = os.environ.get(GROUPS_DIR_ENV)
    if worker is None or folder is None:
        return
    groups = {item.nodeid: group_of(item) for item in items}
    tmp = Path(folder) / f".{worker}.json"
    tmp.write_text(json.dumps(groups))
    tmp.replace(Path(folder) / f"{worker}.json")  # whole, or not there


def make_scheduler(config: pytest.Config, log):
    """A scheduler that hands out the groups above as work units (largest first, as xdist's
    loadscope does); a test no worker recorded is a unit of its own."""
    from xdist.scheduler import LoadScopeScheduling

    class GroupScheduling(LoadScopeScheduling):
        _groups: dict[str, str] | None = None

        def _split_scope(self, nodeid: str) -> str:
            if self._groups is None:
                self._groups = {}
                folder = os.environ.get(GROUPS_DIR_ENV)
                for path in Path(folder).glob("gw*.json") if folder else ():
                    self._groups.update(json.loads(path.read_text()))
            # (a pytest before 9.2 lets xdist append "@group" to the id the worker recorded)
            return self._groups.get(nodeid) or self._groups.get(nodeid.rpartition("@")[0]) or nodeid

    return GroupScheduling(config, log)
