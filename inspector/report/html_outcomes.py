"""The report page's outcomes: success rates per task and overall as bars with their 95% Wilson
intervals as error bars (inline SVG), and the outcome columns of the rollout table."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from html import escape
from typing import Any

Row = dict[str, Any]
_BAR_W, _ROW_H, _LABEL_W, _TEXT_W = 320, 22, 220, 190


def success_section(aggregate: Mapping[str, Any]) -> str:
    """``<h2>Success</h2>`` and one bar per task (and overall): the rate, its interval drawn as an
    error bar, and ``s/n (rate) [lo-hi]`` as text (the page reads without the figure too)."""
    by_task = aggregate.get("success_by_task") or []
    if not by_task:
        return ""
    entries = [*by_task, *([{"task": "overall", **aggregate["success_overall"]}]
                           if aggregate.get("success_overall") and len(by_task) > 1 else [])]
    height = _ROW_H * len(entries) + 24
    width = _LABEL_W + _BAR_W + _TEXT_W
    parts = [f'<svg class="success-rates" role="img" width="{width}" height="{height}" '
             f'viewBox="0 0 {width} {height}" aria-label="success rate per task with 95% intervals">']
    for pct in (0, 50, 100):
        x = _LABEL_W + _BAR_W * pct / 100
        parts.append(f'<line x1="{x:.1f}" y1="0" x2="{x:.1f}" y2="{height - 18}" stroke="#ccc"/>'
                     f'<text x="{x:.1f}" y="{height - 4}" font-size="11" text-anchor="middle">{pct}%</text>')
    for i, e in enumerate(entries):
        y = i * _ROW_H + 4
        lo, hi = e["ci95"]
        rate = e["success_rate"]
        label = escape(str(e["task"]))
        text = f"{e['successes']}/{e['episodes']} ({100 * rate:.0f}%) [{100 * lo:.0f}-{100 * hi:.0f}%]"
        mid = y + _ROW_H / 2 - 2
        x_lo, x_hi = _LABEL_W + _BAR_W * lo, _LABEL_W + _BAR_W * hi
        parts.append(
            f'<g class="success-rate" data-task="{label}" data-lo="{lo:.6f}" data-hi="{hi:.6f}">'
            f"<title>{label}: {escape(text)}, 95% Wilson interval</title>"
            f'<text x="{_LABEL_W - 6}" y="{mid + 4:.1f}" font-size="12" text-anchor="end">{label[:32]}</text>'
            f'<rect x="{_LABEL_W}" y="{y}" width="{_BAR_W * rate:.1f}" height="{_ROW_H - 8}" fill="#4c9a6a"/>'
            f'<line class="error-bar" x1="{x_lo:.1f}" y1="{mid:.1f}" x2="{x_hi:.1f}" y2="{mid:.1f}" '
            f'stroke="#222" stroke-width="1.5"/>'
            f'<line x1="{x_lo:.1f}" y1="{mid - 5:.1f}" x2="{x_lo:.1f}" y2="{mid + 5:.1f}" stroke="#222"/>'
            f'<line x1="{x_hi:.1f}" y1="{mid - 5:.1f}" x2="{x_hi:.1f}" y2="{mid + 5:.1f}" stroke="#222"/>'
            f'<text x="{_LABEL_W + _BAR_W + 8}" y="{mid + 4:.1f}" font-size="12">{escape(text)}</text></g>')
    parts.append("</svg>")
    return ("<h2>Success</h2><p>Success rate per task over the rollouts with an outcome; the bar is "
            "the rate, the error bar its 95% Wilson score interval.</p>" + "".join(parts))


def _outcome(r: Row) -> Mapping[str, Any]:
    return r.get("task_outcome") or {}


def outcome_columns(rows: Sequence[Row]) -> list[tuple[str, str, bool, Callable[[Row], str]]]:
    """(header, tooltip, numeric, cell) of the outcome columns; none when no row has an outcome."""
    if not any(r.get("task_outcome") for r in rows):
        return []

    def success(r: Row) -> str:
        s = _outcome(r).get("success")
        return "-" if s is None else ("yes" if s else "no")

    def progress(r: Row) -> str:
        p = _outcome(r).get("progress")
        return "-" if p is None else f"{p:.0f}"

    return [("success", "did the task succeed (the effective outcome)", False, success),
            ("progress", "how far the task got [%]", True, progress),
            ("failure", "how it failed (failure tag)", False, lambda r: _outcome(r).get("failure") or "-"),
            ("source", "where the outcome comes from: label, file, sim or recording", False,
             lambda r: _outcome(r).get("source") or "-")]
