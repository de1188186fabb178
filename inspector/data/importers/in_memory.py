"""What every importer's ``load_in_memory`` returns: another tool's output imported into a
temporary session, for ``report``, ``serve`` and ``export`` on a raw directory."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from ...errors import InspectorError


class InMemory(NamedTuple):
    """A temporary session: keep ``handle`` alive as long as the session at ``session`` is used;
    ``errors`` holds the rollouts left out ({tag: why})."""

    session: Path
    handle: tempfile.TemporaryDirectory
    errors: dict[str, InspectorError]


def import_temporarily(name: str, run: Callable[[Path], dict[str, InspectorError]]) -> InMemory:
    """Run ``run(dest)`` (an import writing a session at ``dest``, named ``name``, and returning
    the rollouts it left out) into a new temporary directory; a failed import leaves none behind."""
    handle = tempfile.TemporaryDirectory(prefix="inspector-session-")
    dest = Path(handle.name) / name
    try:
        errors = run(dest)
    except BaseException:
        handle.cleanup()
        raise
    return InMemory(dest, handle, errors)
