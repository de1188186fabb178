"""Open whatever a user points at: a session, one rollout of it, or raw DreamZero-SO101 output.

``report``, ``serve`` and ``export`` all take such paths; they share this one function so a path
means the same thing everywhere. Raw model output is imported into a temporary session that lives
as long as the returned :class:`Sources`.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

from .errors import InspectorError
from .session import Rollout, Session, is_rollout, is_session, open_session

BUNDLED_DEMO = Path(__file__).resolve().parent.parent / "sessions" / "demo"


@dataclass
class Sources:
    """Sessions opened from user paths. ``roots`` are the directories the app may read under."""

    sessions: list[Session] = field(default_factory=list)
    roots: list[Path] = field(default_factory=list)
    _temps: list[tempfile.TemporaryDirectory] = field(default_factory=list, repr=False)

    def rollouts(self) -> Iterator[tuple[Session, Rollout]]:
        for session in self.sessions:
            for tag in sorted(session.rollouts):
                yield session, session.rollouts[tag]

    def close(self) -> None:
        for t in self._temps:
            t.cleanup()
        self._temps.clear()


def open_sources(paths: Sequence[str | Path], dataset: str | Path | None = None) -> Sources:
    """Open each path as a session (a rollout path opens its session filtered to that rollout).

    Args:
        paths: sessions, rollout directories, or DreamZero-SO101 source directories.
        dataset: a LeRobot dataset to take GT from when a session names none.

    Raises:
        InspectorError: a path is missing or is none of the above.
    """
    out = Sources()
    try:
        for raw in paths:
            _open_one(out, raw, dataset)
    except BaseException:
        out.close()  # temporary sessions of the paths already opened
        raise
    return out


def _open_one(out: Sources, raw: str | Path, dataset: str | Path | None) -> None:
    """Open one path of :func:`open_sources` into ``out``."""
    path = Path(os.path.expanduser(raw))  # '~nosuchuser' stays as it is: not found
    if not path.exists():
        raise InspectorError(path, "not found")
    path = path.resolve()
    if is_session(path):
        session = open_session(path)
    elif is_rollout(path) and is_session(path.parent.parent):
        session = open_session(path.parent.parent)
        keep = path.name
        session.rollouts = {k: v for k, v in session.rollouts.items() if k == keep}
        session.errors = {k: v for k, v in session.errors.items() if k == keep}
    else:
        from .importers.dreamzero_so101 import find_sources, load_in_memory

        find_sources(path)  # raises a clear error when there is nothing to import
        session_path, handle = load_in_memory(path, dataset=dataset)
        out._temps.append(handle)
        session = open_session(session_path)
        out.roots.append(Path(handle.name))
    if dataset is not None and session.dataset_root is None:
        from .lerobot_dataset import find_dataset

        session.gt_source["dataset"] = str(find_dataset(dataset))
    out.sessions.append(session)
    out.roots.append(session.root.resolve())
