"""A rollout's outcomes in its recording: every source as static markdown (``/outcome``, the
effective one first) and the effective success (1 / 0) and progress [%] as series over the
rollout (``/plots/outcome/success``, ``/plots/outcome/progress``), so a shared file says whether
the task succeeded, and by whose account."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import rerun as rr

from ..analysis.timeline import RolloutTimeline
from ..errors import InspectorError
from ..outcomes import effective_outcome, load_session_outcomes
from .series import log_series

OUTCOME = "outcome"
SUCCESS_SERIES, PROGRESS_SERIES = "plots/outcome/success", "plots/outcome/progress"
IndexesFor = Callable[[np.ndarray], list]


def rollout_outcomes(tl: RolloutTimeline) -> dict[str, Any]:
    """Every source's record of the timeline's rollout (none for a dataset episode or without a
    session; an unreadable outcomes file counts as none: the recording is still written)."""
    session = tl.rollout.session
    if session is None or tl.kind == "episode":
        return {}
    try:
        found = load_session_outcomes(session)
    except InspectorError:
        return {}
    return found.sources(tl.tag, session.rollouts.get(tl.tag, tl.rollout))


def outcome_markdown(sources: Mapping[str, Any], shown: Mapping[str, Any] | None) -> str:
    def cell(v: Any) -> str:
        return "-" if v is None or v == "" else str(v).replace("|", "\\|").replace("\n", " ")

    lines = ["# Outcome", ""]
    if shown is not None:
        verdict = {True: "success", False: "failure", None: "not said"}[shown["success"]]
        lines += [f"**{verdict}** (source: {shown['source']})", ""]
    lines += ["| source | success | progress % | failure | note | set at | set by |", "|---|---|---|---|---|---|---|"]
    for source, r in sources.items():
        lines.append(f"| {source} | {cell(r['success'])} | {cell(r['progress'])} | {cell(r['failure'])} | "
                     f"{cell(r['note'])} | {cell(r['set_at'])} | {cell(r['set_by'])} |")
    return "\n".join(lines) + "\n"


def log_outcomes(rec: rr.RecordingStream, tl: RolloutTimeline, indexes_for: IndexesFor,
                 outcome_source: str | None = None) -> bool:
    """Log the outcome text (every source) and the series of the one shown: ``outcome_source``'s
    (``--outcome-source``), else the precedence rule's. False when the rollout has no outcome."""
    sources = rollout_outcomes(tl)
    if not sources:
        return False
    shown = effective_outcome(sources, outcome_source)
    rec.log(OUTCOME, rr.TextDocument(outcome_markdown(sources, shown), media_type="text/markdown"), static=True)
    if shown is not None:
        ends = np.array([0, max(tl.n_steps - 1, 0)])
        if shown["success"] is not None:
            log_series(rec, SUCCESS_SERIES, ends, np.full(2, float(shown["success"])), indexes_for,
                       "success (1 = yes)", (43, 138, 62, 255))
        if shown["progress"] is not None:
            log_series(rec, PROGRESS_SERIES, ends, np.full(2, float(shown["progress"])), indexes_for,
                       "progress %", (240, 140, 0, 255))
    return True
