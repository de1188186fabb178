"""Sessions opened for ranking and agreement, and what each rollout's effective outcome says
(:func:`inspector.outcomes.effective_outcome`: a person's label, else a judge's file, else the
simulator's verdict, else the recording's ``next.success``)."""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..data.session import Rollout, Session, is_session, open_session
from ..errors import InspectorError
from ..outcomes import SessionOutcomes, effective_outcome, load_session_outcomes


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
    """One rollout's outcome: success (None when not judged) and progress as a fraction 0..1 of the
    task (None when not scored; the outcome records keep it in percent)."""

    success: bool | None
    progress: float | None


def session_outcomes(session: Session) -> SessionOutcomes:
    """The session's outcomes from every source.

    Raises:
        InspectorError: its outcomes file (or its dataset's ``next.success``) cannot be read.
    """
    outcomes = load_session_outcomes(session)
    if outcomes.error is not None:
        raise outcomes.error
    return outcomes


def judged(outcomes: SessionOutcomes, tag: str, rollout: Rollout, prefer: str | None = None) -> Judged:
    """A rollout's effective outcome, or the ``prefer`` source's alone (``--outcome-source``)."""
    record = effective_outcome(outcomes.sources(tag, rollout), prefer)
    if record is None:
        return Judged(None, None)
    progress = record.get("progress")
    return Judged(record.get("success"),
                  None if progress is None or not math.isfinite(progress) else float(progress) / 100.0)


def task_of(rollout: Rollout) -> str:
    """The task a rollout attempted: its prompt, else its outcome's task name."""
    if rollout.prompt:
        return rollout.prompt
    outcome = rollout.extra.get("outcome")
    return str(outcome.get("task")) if isinstance(outcome, dict) and outcome.get("task") is not None else ""
