"""The Overview's outcomes: each row's effective outcome (a label, an imported file, a simulated
evaluation's verdict, the GT dataset's ``next.success``; or the ``--outcome-source`` alone), read
at each redraw (one outcomes file per session), so a label made in any tab shows in every tab's
table; and the success rates with their 95% Wilson intervals."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from html import escape
from typing import Any

from ..errors import InspectorError
from ..outcomes import outcomes_path, read_outcomes
from ..report.outcomes import percent_interval
from ..rows.outcomes import rate_record
from ._overview_rows import OverviewRow


def row_outcomes(rows: Sequence[OverviewRow], catalog: Any) -> tuple[dict[str, dict[str, Any] | None], InspectorError | None]:
    """Catalog key -> effective outcome (None: none) of each row of a served session, as
    ``catalog.outcomes`` picks it, and the first unreadable outcomes file's (or GT column's) error."""
    documents: dict[Any, Any] = {}
    out: dict[str, dict[str, Any] | None] = {}
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
            error = error or catalog.outcomes.recorded(entry.session)[1]
        shown = catalog.outcomes.shown(catalog.outcomes.sources(entry.session, r.tag, documents[path]))
        out[r.key] = None if shown is None else dict(shown)
    return out, error


def success_rate_html(shown: Sequence[OverviewRow], outcomes: Mapping[str, Mapping[str, Any] | None]) -> str:
    """``success 12/20 (60%, 95% CI 39-78%) · 20 of 60 with an outcome`` over the rows shown."""
    flags = [o["success"] for r in shown if (o := outcomes.get(r.key)) is not None and o.get("success") is not None]
    if not flags:
        return ""
    record = rate_record(sum(flags), len(flags))
    return (f"<div class='ov-success' data-lo='{record['ci95'][0]:.6f}' data-hi='{record['ci95'][1]:.6f}'>"
            f"success {escape(percent_interval(record))} over the {len(flags)} shown row(s) with an outcome "
            f"(Wilson interval)</div>")
