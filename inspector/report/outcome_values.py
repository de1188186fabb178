"""Sessions opened for ranking and agreement, and what each rollout's outcome says.

A rollout's outcome lives in its ``extra.outcome`` (a simulated evaluation's verdict, a judge's
file, a person's label): ``success`` (true/false) and, where judged, ``progress`` (0 to 1).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..data.session import Rollout, Session, is_session, open_session
from ..errors import InspectorError


def open_sessions(paths: Sequence[str | Path], flag: str = "PATH") -> list[Session]:
    """Each path opened as a session (arrays unread), in order.

    Raises:
        InspectorError: a path that is not a session directory, or the same session twice.
    """
    sessions: list[Session] = []
    seen: set[Path] = set()
    for path in paths:
        if not is_session(path):
            raise InspectorError(path, f"not a session directory (no session.json){'' if flag == 'PATH' else f' ({flag})'}")
        session = open_session(path, lazy=True)
        resolved = session.root.resolve()
        if resolved in seen:
            raise InspectorError(path, "the same session is given twice")
        seen.add(resolved)
        sessions.append(session)
    return sessions


def session_labels(sessions: Sequence[Session]) -> list[str]:
    """A short unique label per session: its name, or its directory's name where names repeat
    (two copies of one session), or its path where those repeat too."""
    names = Counter(s.name for s in sessions)
    dirs = Counter(s.root.name for s in sessions)
    return [s.name if names[s.name] == 1 else s.root.name if dirs[s.root.name] == 1 else str(s.root)
            for s in sessions]


def model_label(session: Session) -> str:
    """The checkpoint a session evaluated: ``model.name`` and ``model.checkpoint`` from
    ``session.json`` (``name@checkpoint``), else the session's name."""
    model = session.model or {}
    name, checkpoint = model.get("name"), model.get("checkpoint")
    if name and checkpoint:
        return f"{name}@{checkpoint}"
    return str(name or checkpoint or session.name)


@dataclass(frozen=True)
class Judged:
    """One rollout's outcome: success (None when not judged) and progress (None when not scored)."""

    success: bool | None
    progress: float | None


def judged(rollout: Rollout) -> Judged:
    outcome: Any = rollout.extra.get("outcome")
    if not isinstance(outcome, dict):
        return Judged(None, None)
    success = outcome.get("success")
    progress = outcome.get("progress")
    return Judged(success if isinstance(success, bool) else None,
                  float(progress) if isinstance(progress, (int, float)) and not isinstance(progress, bool)
                  and math.isfinite(progress) else None)


def task_of(rollout: Rollout) -> str:
    """The task a rollout attempted: its prompt, else its outcome's task name."""
    if rollout.prompt:
        return rollout.prompt
    outcome = rollout.extra.get("outcome")
    return str(outcome.get("task")) if isinstance(outcome, dict) and outcome.get("task") is not None else ""
