"""Outcomes in the report's text: success rates per task and overall with their intervals, and
each rollout's outcome (the rows carry them: :mod:`inspector.rows.outcomes`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..rows.outcomes import Row


def percent_interval(record: Mapping[str, Any]) -> str:
    """``18/20 (90%, 95% CI 70-97%)``."""
    lo, hi = record["ci95"]
    return (f"{record['successes']}/{record['episodes']} ({100 * record['success_rate']:.0f}%, "
            f"95% CI {100 * lo:.0f}-{100 * hi:.0f}%)")


def success_lines(aggregate: Mapping[str, Any]) -> list[str]:
    """The text report's success rates per task and overall."""
    by_task = aggregate.get("success_by_task") or []
    if not by_task:
        return []
    lines = ["Success rate per task (95% Wilson interval)"]
    for t in by_task:
        extra = "".join([f", mean progress {t['mean_progress']:.0f}%" if t.get("mean_progress") is not None else "",
                         f", mean reward {t['mean_sum_reward']:.3g}" if t.get("mean_sum_reward") is not None else ""])
        lines.append(f"  {t['task']}: {percent_interval(t)}{extra}")
    if (overall := aggregate.get("success_overall")) is not None:
        lines.append(f"  overall: {percent_interval(overall)}")
    return [*lines, ""]


def outcome_lines(rows: list[Row]) -> list[str]:
    """Rows with an effective outcome that no simulated evaluation's table shows already."""
    shown = [r for r in rows if r.get("task_outcome") and not r.get("outcome")]
    if not shown:
        return []
    width = max([18] + [len(r["tag"]) for r in shown])
    lines = ["Outcomes", f"{'rollout':<{width}} {'success':>7} {'progress':>8} {'failure':>13} {'source':>9}  note"]
    for r in shown:
        o = r["task_outcome"]
        success = "-" if o["success"] is None else ("yes" if o["success"] else "no")
        progress = "-" if o["progress"] is None else f"{o['progress']:.0f}%"
        lines.append(f"{r['tag']:<{width}} {success:>7} {progress:>8} {o['failure'] or '-':>13} {o['source']:>9}  "
                     f"{o['note']}")
    return [*lines, ""]
