"""The outcomes of the served rollouts as the app shows them: every source of a rollout (the stored
``label`` and ``file`` records, read fresh each time so a label made in any tab or process shows
at once; a simulated evaluation's ``sim`` verdict; the GT dataset's ``recording``, read once per
session) and the one the tables use, by the precedence rule or the ``--outcome-source`` the app
was started with. Labels a person makes are saved as source ``label`` whatever is shown."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import InspectorError
from ..outcomes import OutcomeRecord, effective_outcome, rollout_sources, session_recording_outcomes


class ServedOutcomes:
    """Outcome sources of the served sessions, shared by every tab.

    Args:
        prefer: the source the tables use (``--outcome-source``); None: the precedence rule.
    """

    def __init__(self, prefer: str | None = None) -> None:
        self.prefer = prefer
        self._lock = threading.Lock()
        # session root -> its GT dataset's recorded outcomes (a dataset does not change while served)
        self._recorded: dict[Path, tuple[dict[int, OutcomeRecord], InspectorError | None]] = {}

    def recorded(self, session: Any) -> tuple[dict[int, OutcomeRecord], InspectorError | None]:
        """The session's ``recording`` records per episode, and why they could not be read."""
        with self._lock:
            if session.root not in self._recorded:
                try:
                    self._recorded[session.root] = (session_recording_outcomes(session), None)
                except InspectorError as exc:
                    self._recorded[session.root] = ({}, exc)
            return self._recorded[session.root]

    def sources(self, session: Any, tag: str, stored: Mapping[str, Any]) -> dict[str, OutcomeRecord]:
        """Every source's record of ``session``'s rollout ``tag`` (``stored``: its outcomes file's
        ``rollouts``)."""
        return rollout_sources(tag, session.rollouts.get(tag), stored, self.recorded(session)[0])

    def shown(self, sources: Mapping[str, OutcomeRecord]) -> OutcomeRecord | None:
        """The outcome the tables use."""
        return effective_outcome(sources, self.prefer)
