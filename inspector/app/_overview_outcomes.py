"""The Overview's outcomes: each row's effective outcome (a label, an imported file, a simulated
evaluation's verdict), read at each redraw (one outcomes file per session), so a label made in any
tab shows in every tab's table; and the success rates with their 95% Wilson intervals."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from html import escape
from typing import Any

from ..errors import InspectorError
from ..outcomes import effective_outcome, outcomes_path, read_outcomes, rollout_sources
from ..report.outcomes import percent_interval, rate_record
from ._overview_rows import OverviewRow


def row_outcomes(rows: Sequence[OverviewRow], catalog: Any) -> tuple[dict[str, dict[str, Any]], InspectorError | None]:
    """Catalog key -> effective outcome of each row with one (and the first unreadable file's error)."""
    documents: dict[Any, Any] = {}
    out: dict[str, dict[str, Any]] = {}
    error = None
    for r in rows:
        entry = catalog.get(r.key)
        if entry is None or entry.session is None:
            continue
        path = outcomes_path(entry.session)
        if path not in documents:
            try:
                documents[path] = read_outcomes(path)["rollouts"]
            except InspectorError as exc:
                error = error or exc
                documents[path] = {}
        sources = rollout_sources(r.tag, entry.session.rollouts.get(r.tag), documents[path], {})
        shown = effective_outcome(sources)
        if shown is not None:
            out[r.key] = dict(shown)
    return out, error


def success_rate_html(shown: Sequence[OverviewRow], outcomes: Mapping[str, Mapping[str, Any]]) -> str:
    """``success 12/20 (60%, 95% CI 39-78%) · 20 of 60 with an outcome`` over the rows shown."""
    flags = [o["success"] for r in shown if (o := outcomes.get(r.key)) and o.get("success") is not None]
    if not flags:
        return ""
    record = rate_record(sum(flags), len(flags))
    return (f"<div class='ov-success' data-lo='{record['ci95'][0]:.6f}' data-hi='{record['ci95'][1]:.6f}'>"
            f"success {escape(percent_interval(record))} over the {len(flags)} shown row(s) with an outcome "
            f"(Wilson interval)</div>")
