"""Outcomes on report rows: every source's record on each row, the effective one, and success
rates per task and overall with their Wilson intervals.

The records are attached after the metrics (never cached with them): a label made a second ago is
in the next report, whatever the metrics cache holds.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..data.episodes import episode_tag
from ..data.lerobot_dataset import LeRobotDataset
from ..errors import InspectorError
from ..outcomes import effective_outcome, load_session_outcomes, recording_outcomes
from ..stats import wilson_interval

Row = dict[str, Any]


def attach_outcomes(sources: Any, rows: Mapping[tuple[str, str], Row], prefer: str | None = None) -> list[str]:
    """Set ``outcome_sources`` (every source's record) and ``task_outcome`` (the effective one, see
    :func:`inspector.outcomes.effective_outcome`) on each row of ``rows`` ((root, tag) -> row) that
    belongs to ``sources``' sessions or datasets. Returns warnings (an outcomes file that cannot
    be read: the report goes on without it, and the file is left as it is)."""
    warnings = []
    for session in sources.sessions:
        found = load_session_outcomes(session)
        if found.error is not None:
            warnings.append(f"outcomes not read: {found.error}")
        root = str(session.root)
        for tag in [*session.rollouts, *session.errors]:
            row = rows.get((root, tag))
            if row is not None:
                _set(row, found.sources(tag, session.rollouts.get(tag)), prefer)
    for dataset in sources.datasets:
        if not isinstance(dataset, LeRobotDataset):
            continue
        try:
            recorded = recording_outcomes(dataset)
        except InspectorError as exc:
            warnings.append(f"outcomes not read: {exc}")
            continue
        for index, record in recorded.items():
            row = rows.get((str(dataset.root), episode_tag(index)))
            if row is not None:
                _set(row, {"recording": record}, prefer)
    return warnings


def _set(row: Row, by_source: dict[str, Any], prefer: str | None) -> None:
    row["outcome_sources"] = by_source
    row["task_outcome"] = effective_outcome(by_source, prefer)


def task_of(row: Row) -> str:
    """The task a row's success counts toward: a simulated evaluation's task, else the prompt."""
    sim = row.get("outcome")
    if isinstance(sim, dict) and sim.get("task") is not None:
        return str(sim["task"])
    return str(row.get("prompt") or row.get("task") or "")


def rate_record(successes: int, n: int) -> dict[str, Any]:
    lo, hi = wilson_interval(successes, n)
    return {"episodes": n, "successes": successes, "success_rate": successes / n if n else None,
            "ci95": [lo, hi]}


def success_by_task(rows: list[Row]) -> list[dict[str, Any]]:
    """Per task (in the order the tasks first appear), over the rows whose effective outcome says
    success or failure: episodes, successes, the success rate and its 95% Wilson interval
    (``ci95``), the mean progress [%] and a simulated evaluation's mean summed reward."""
    tasks: dict[str, list[Row]] = defaultdict(list)
    for r in rows:
        if (r.get("task_outcome") or {}).get("success") is not None:
            tasks[task_of(r)].append(r)
    out = []
    for task, task_rows in tasks.items():
        n_success = sum(bool(r["task_outcome"]["success"]) for r in task_rows)
        rewards = [r["outcome"]["sum_reward"] for r in task_rows
                   if isinstance(r.get("outcome"), dict) and r["outcome"].get("sum_reward") is not None]
        progress = [r["task_outcome"]["progress"] for r in task_rows if r["task_outcome"].get("progress") is not None]
        out.append({"task": task, **rate_record(n_success, len(task_rows)),
                    "mean_progress": float(np.mean(progress)) if progress else None,
                    "mean_sum_reward": float(np.mean(rewards)) if rewards else None})
    return out


def success_overall(by_task: list[dict[str, Any]]) -> dict[str, Any] | None:
    """All tasks together (the same rows as :func:`success_by_task`), or None without outcomes."""
    if not by_task:
        return None
    return rate_record(sum(t["successes"] for t in by_task), sum(t["episodes"] for t in by_task))
