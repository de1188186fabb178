"""The outcomes the data itself carries (``sim``, ``recording``), beside the stored ones."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import InspectorError
from ..said.outcome_record import RECORDING_SUCCESS, SOURCES, OutcomeRecord, OutcomesDocument, make_record
from ..said.outcome_store import empty_document, outcomes_path, read_outcomes
from ..schema import shown

if TYPE_CHECKING:
    from ..data.lerobot_dataset import LeRobotDataset
    from ..data.session import Rollout, Session



def sim_record(outcome: Any) -> OutcomeRecord | None:
    """The ``sim`` record of a rollout's ``extra.outcome`` (a lerobot-eval verdict), or None."""
    if not isinstance(outcome, dict) or outcome.get("success") is None:
        return None
    return make_record("sim", success=bool(outcome["success"]), set_by="eval_info.json")


def recording_outcomes(dataset: LeRobotDataset) -> dict[int, OutcomeRecord]:
    """Per episode index, the ``recording`` record of a dataset with ``next.success``: success
    when any frame of the episode says so. Empty when the dataset has no such column.

    Raises:
        InspectorError: a data file that cannot be read or a column of the wrong type.
    """
    if RECORDING_SUCCESS not in dataset.features:
        return {}
    import pyarrow.parquet as pq

    out: dict[int, OutcomeRecord] = {}
    files = sorted({e.data_file for e in dataset.episodes})
    for f in files:
        try:
            table = pq.read_table(f, columns=["episode_index", RECORDING_SUCCESS])
            episodes = table.column("episode_index").to_pylist()
            success = table.column(RECORDING_SUCCESS).to_pylist()
        except Exception as exc:
            raise InspectorError(f, f"{RECORDING_SUCCESS}: cannot read ({type(exc).__name__}: {exc})") from None
        seen: dict[int, bool] = {}
        for ep, ok in zip(episodes, success):
            if not isinstance(ok, (bool, int)) or isinstance(ok, float):
                raise InspectorError(f, f"{RECORDING_SUCCESS}: expected booleans, found {shown(ok)}")
            seen[int(ep)] = seen.get(int(ep), False) or bool(ok)
        for ep, ok in seen.items():
            out[ep] = make_record("recording", success=ok, set_by=str(dataset.root))
    return out


def rollout_sources(tag: str, rollout: Rollout | None, stored: Mapping[str, Any],
                    recording: Mapping[int, OutcomeRecord]) -> dict[str, OutcomeRecord]:
    """Every source's record of one rollout: stored (label, file), sim, recording."""
    out: dict[str, OutcomeRecord] = dict(stored.get(tag, {}))
    if rollout is not None:
        sim = sim_record(rollout.extra.get("outcome") if isinstance(rollout.extra, dict) else None)
        if sim is not None:
            out["sim"] = sim
        if rollout.episode_index is not None and rollout.episode_index in recording and sim is None:
            out["recording"] = recording[rollout.episode_index]
    return {s: out[s] for s in SOURCES if s in out}


@dataclass
class SessionOutcomes:
    """The outcomes of one loaded session: every source per rollout, read once."""

    path: Path
    document: OutcomesDocument
    recording: dict[int, OutcomeRecord] = field(default_factory=dict)
    error: InspectorError | None = None

    def sources(self, tag: str, rollout: Rollout | None) -> dict[str, OutcomeRecord]:
        return rollout_sources(tag, rollout, self.document["rollouts"], self.recording)


def load_session_outcomes(session: Session) -> SessionOutcomes:
    """Read a session's stored outcomes and its GT dataset's ``next.success``; a broken outcomes
    file (or dataset column) is kept in ``error`` and the session goes on without it."""
    path = outcomes_path(session)
    try:
        document = read_outcomes(path)
        error = None
    except InspectorError as exc:
        document, error = empty_document(), exc
    out = SessionOutcomes(path, document, error=error)
    try:
        out.recording = session_recording_outcomes(session)
    except InspectorError as exc:
        out.error = out.error or exc
    return out


def session_recording_outcomes(session: Session) -> dict[int, OutcomeRecord]:
    """Per episode index, the ``recording`` record of the session's GT dataset (empty without one,
    or when it has no ``next.success``).

    Raises:
        InspectorError: the dataset's column cannot be read.
    """
    root = session.dataset_root
    if root is None or not root.is_dir():
        return {}
    from ..data.lerobot_dataset import open_dataset

    return recording_outcomes(open_dataset(root))


