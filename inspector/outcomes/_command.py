"""``inspector outcomes import FILE PATH``: a judge's, a run sheet's or a script's outcomes, stored
as the ``file`` source of the rollouts they name."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from ..data.sources import open_sources
from ..errors import InspectorError
from ..said.outcome_store import known_failure_tags, outcomes_path, read_outcomes, store_records
from ._import_file import FileRow, iter_outcome_file, match_rows


@dataclass
class Imported:
    store: Path  # the outcomes file written (a session's outcomes.json or a raw directory's sidecar)
    rows: int
    rollouts: int
    unmatched: list[FileRow]  # the first rows that match no rollout (MAX_UNMATCHED_LISTED)
    unmatched_rows: int = 0  # all of them


def import_outcomes(file: str | Path, path: str | Path, add_tags: Sequence[str] = ()) -> Imported:
    """Store the rows of ``file`` as the ``file`` outcomes of the rollouts of ``path`` (a session,
    or a raw directory imported in memory: then in its sidecar) in one atomic write.

    Raises:
        InspectorError: ``file`` is bad (line and field named; nothing is written), no row of it
            matches a rollout, or ``path`` holds no rollouts or a broken outcomes file.
    """
    sources = open_sources([path], lazy=True)
    try:
        if not sources.sessions:
            raise InspectorError(path, "not a session or a directory with rollouts")
        session = sources.sessions[0]
        store = outcomes_path(session)
        known = (*known_failure_tags(read_outcomes(store)), *add_tags)
        result = match_rows(iter_outcome_file(file, known), session.rollouts)  # streamed: see match_rows
        if not result.matched:
            first = result.first
            assert first is not None  # a file without rows is refused as it is read
            raise InspectorError(file, f"no row matches a rollout of {path} (line {first.line}: {first.names()}; "
                                       f"rollouts: {', '.join(sorted(session.rollouts)[:5])}"
                                       f"{', ...' if len(session.rollouts) > 5 else ''})")
        try:
            store_records(store, result.matched, source="file", set_by=Path(file).name, add_tags=add_tags)
        except ValueError as exc:
            raise InspectorError(store, str(exc)) from None
        return Imported(store, result.rows - result.unmatched_rows, len(result.matched), result.unmatched,
                        result.unmatched_rows)
    finally:
        sources.close()
