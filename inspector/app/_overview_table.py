"""What the overview shows, as plain functions of its rows: which rows a query selects and in what
order, the table, the compare summary and the figures, as HTML for viser's HTML elements.

No GUI here (see :mod:`._overview`), so tests check selection and rendering directly. Numbers are
in the data's units as everywhere else: joints in degrees (the gripper's 0..100 counts as is),
end-effector error in mm, PSNR in dB. The figures are the HTML report's
(:func:`inspector.report.figures.report_figures`, drawn by :func:`inspector.report.html.figure_html`),
styled by the report's ``chart.css`` scoped under the overview's element.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from html import escape
from importlib import resources
from typing import Any, cast

from ..analysis.video_action import median_lag_label
from ..outcomes import sim_record
from ..report.compare import compare_reports
from ..report.figures import report_figures
from ..report.html import KIND_LABELS, figure_html
from ..report.significance import verdict_parts
from ..rows.rollout import limit_steps
from ._overview_rows import OverviewRow

SCOPE = "inspector-overview"  # the class of the overview's elements; its styles apply under it
ALL_KINDS, ALL_SESSIONS, NO_COMPARE = "all kinds", "all sessions", "— none —"
FAILED = "failed episodes"  # a simulated evaluation's episodes that did not succeed
KIND_FILTERS = {ALL_KINDS: None, "single-chunk": "single_chunk", "autoregressive": "autoregressive",
                "open-loop replay": "open_loop_replay", "errors": "error", FAILED: "failed"}
ALL_OUTCOMES, UNLABELLED, SUCCEEDED, FAILED_OUTCOME = "all outcomes", "without a label", "succeeded", "failed"
TAG_FILTER = "failure: "  # + a tag
PICKER_ORDER = "picker order"
DELTA_RMSE = "Δ RMSE (B − A)"
# Rows drawn in the table at most: the page holds what is on screen, filters narrow the rest.
MAX_TABLE_ROWS = 200
MAX_NOTE_CHARS = 60

Summary = dict[str, Any]


def _drift(name: str, field_: str) -> Callable[[Summary], float | None]:
    return lambda s: s[name][field_] if s.get(name) else None


# Sortable metrics: label -> value of a row's summary (None: no value; sorted last either way).
METRICS: dict[str, Callable[[Summary], float | None]] = {
    "RMSE": lambda s: s["rmse_deg"],
    "time-aligned mean": _drift("time_aligned_drift", "mean"),
    "time-aligned final": _drift("time_aligned_drift", "final"),
    "best-match mean": _drift("best_match_drift", "mean"),
    "best-match final": _drift("best_match_drift", "final"),
    "tempo": lambda s: s["tempo"],
    "EE error": _drift("ee_error_mm", "mean"),
    "limit steps": limit_steps,
    "reward": lambda s: (s.get("outcome") or {}).get("sum_reward"),
    # the sanity measures (docs/metrics.md); rows cached before them have none
    "worst seam": lambda s: ((s.get("seams") or {}).get("worst") or {}).get("jump_deg"),
    "completion s": lambda s: (s.get("completion") or {}).get("time_s"),
    "coupling": lambda s: max(c["coupling_error_deg"].values())
    if (c := s.get("joint_coherence")) and c["coupling_error_deg"] else None,
    "video break": lambda s: min(breaks) if (breaks := [b for b in (s.get("video_break") or {}).values()
                                                        if b is not None]) else None,
}


def outcome_of(row: OverviewRow) -> dict[str, Any] | None:
    """A simulated evaluation's verdict for the row (success, rewards, task), or None."""
    return row.summary.get("outcome") if row.summary else None


def psnr_label(view: str) -> str:
    return f"PSNR {view}"


@dataclass(frozen=True)
class Query:
    """What the overview's controls ask for.

    Attributes:
        sort: :data:`PICKER_ORDER`, a :data:`METRICS` label, a :func:`psnr_label`, ``"flag"``
            or :data:`DELTA_RMSE`.
        descending: largest first (rows without a value stay last).
        search: words that must all occur in the prompt or tag (case-insensitive).
        kind: a :data:`KIND_FILTERS` label.
        session: :data:`ALL_SESSIONS` or a session's name.
        flagged_only, violations_only: keep flagged rows / rows with steps past a joint limit.
        compare_with: :data:`NO_COMPARE` or the name of session B (the table's rows are A).
        outcome: an :func:`outcome_filters` label: all, unlabelled, succeeded, failed, or a failure tag.
    """

    sort: str = PICKER_ORDER
    descending: bool = False
    search: str = ""
    kind: str = ALL_KINDS
    session: str = ALL_SESSIONS
    flagged_only: bool = False
    violations_only: bool = False
    compare_with: str = NO_COMPARE
    outcome: str = ALL_OUTCOMES


@dataclass(frozen=True)
class Note:
    """A rollout's flag and note from its session's annotations.json, and its effective outcome
    (:func:`inspector.outcomes.effective_outcome`; None: none)."""

    flag: bool = False
    note: str = ""
    outcome: Mapping[str, Any] | None = None
    # the outcome was read from every source (None then means none, not yet unread: a simulated
    # evaluation's verdict is not put in its place, as ``--outcome-source label`` may leave it out)
    outcome_read: bool = False


@dataclass
class Comparison:
    """The table's rows (A) against session B, paired by :func:`inspector.report.compare.pair_rows`.

    Attributes:
        session_b: B's name.
        result: :func:`inspector.report.compare.compare_reports` of the computed rows.
        pair_of: A's key -> (B's key, ``delta_rmse_deg``, ``delta_time_aligned_drift_deg``).
        waiting: rows of either side still computing.
    """

    session_b: str
    result: dict[str, Any]
    pair_of: dict[str, tuple[str, float | None, float | None]] = field(default_factory=dict)
    waiting: int = 0


def views_of(rows: Sequence[OverviewRow]) -> list[str]:
    """Camera views with a PSNR in some row."""
    return sorted({v for r in rows if r.summary for v in r.summary["video_psnr_db"]})


def sort_options(rows: Sequence[OverviewRow], comparing: bool = False) -> list[str]:
    return [PICKER_ORDER, *METRICS, *map(psnr_label, views_of(rows)), "flag", "success", "progress",
            *([DELTA_RMSE] if comparing else [])]


def _kind_of(row: OverviewRow) -> str:
    return "error" if row.error is not None else row.kind


def _matches(row: OverviewRow, q: Query, notes: Mapping[str, Note]) -> bool:
    if q.session != ALL_SESSIONS and row.session != q.session:
        return False
    kind = KIND_FILTERS.get(q.kind)
    if kind == "failed":
        if (effective_of(row, notes) or {}).get("success") is not False:
            return False
    elif kind is not None and _kind_of(row) != kind:
        return False
    if q.flagged_only and not notes.get(row.key, Note()).flag:
        return False
    if q.outcome != ALL_OUTCOMES and not _outcome_matches(effective_of(row, notes), q.outcome):
        return False
    if q.violations_only and not (row.summary and (limit_steps(row.summary) or 0) > 0):
        return False
    text = f"{row.prompt} {row.tag}".lower()
    return all(word in text for word in q.search.lower().split())


def effective_of(row: OverviewRow, notes: Mapping[str, Note]) -> Mapping[str, Any] | None:
    """The row's effective outcome: as read with its notes, else its simulated evaluation's verdict."""
    note = notes.get(row.key, Note())
    return note.outcome if note.outcome_read else note.outcome or sim_record(outcome_of(row))


def outcome_filters(notes: Mapping[str, Note]) -> list[str]:
    """The outcome filter's options: all, unlabelled, succeeded, failed and each failure tag in use."""
    tags = sorted({str(n.outcome["failure"]) for n in notes.values() if n.outcome and n.outcome.get("failure")})
    return [ALL_OUTCOMES, UNLABELLED, SUCCEEDED, FAILED_OUTCOME, *(TAG_FILTER + t for t in tags)]


def _outcome_matches(outcome: Mapping[str, Any] | None, wanted: str) -> bool:
    if wanted == UNLABELLED:
        return outcome is None or outcome.get("source") != "label"
    if outcome is None:
        return False
    if wanted == SUCCEEDED:
        return outcome.get("success") is True
    if wanted == FAILED_OUTCOME:
        return outcome.get("success") is False
    return wanted.startswith(TAG_FILTER) and outcome.get("failure") == wanted.removeprefix(TAG_FILTER)


def sort_value(row: OverviewRow, sort: str, notes: Mapping[str, Note],
               comparison: Comparison | None = None) -> float | None:
    """The value a row sorts by (None: none; such rows come last)."""
    if sort == "flag":
        return 1.0 if notes.get(row.key, Note()).flag else 0.0
    if sort in ("success", "progress"):
        value = (effective_of(row, notes) or {}).get(sort)
        return None if value is None else float(value)
    if sort == DELTA_RMSE:
        pair = comparison.pair_of.get(row.key) if comparison is not None else None
        return pair[1] if pair is not None else None
    if row.summary is None:
        return None
    if sort in METRICS:
        return METRICS[sort](row.summary)
    if sort.startswith("PSNR "):
        return row.summary["video_psnr_db"].get(sort.removeprefix("PSNR "))
    return None


def select_rows(rows: Sequence[OverviewRow], q: Query, notes: Mapping[str, Note],
                comparison: Comparison | None = None) -> list[OverviewRow]:
    """The rows ``q`` keeps, in its order (picker order among equals; without a value, last).

    While comparing, session B's rows are the other side of the comparison, not table rows.
    """
    kept = [r for r in rows if _matches(r, q, notes)
            and (comparison is None or r.session != comparison.session_b)]
    if q.sort == PICKER_ORDER:
        return kept[::-1] if q.descending else kept
    valued = [(sort_value(r, q.sort, notes, comparison), i, r) for i, r in enumerate(kept)]
    have = sorted((t for t in valued if t[0] is not None),
                  key=lambda t: (-cast(float, t[0]) if q.descending else t[0], t[1]))
    return [r for _, _, r in have] + [r for v, _, r in valued if v is None]


# ----------------------------------------------------------------------------------------------
# Compare


def compare_with_session(rows: Sequence[OverviewRow], q: Query, notes: Mapping[str, Note]) -> Comparison | None:
    """The table's rows (A: what the filters keep, B's own rows aside) against session B's rows,
    over the rows computed so far; None when not comparing."""
    if q.compare_with == NO_COMPARE:
        return None
    side_a = [r for r in rows if r.session != q.compare_with and _matches(r, q, notes)]
    side_b = [r for r in rows if r.session == q.compare_with]
    done_a, done_b = [r for r in side_a if r.summary], [r for r in side_b if r.summary]
    # each row with its effective outcome, so the comparison tests success too
    with_outcome = {r.key: {**cast(dict, r.summary), "task_outcome": effective_of(r, notes)} for r in done_a + done_b}
    key_of = {id(summary): key for key, summary in with_outcome.items()}
    result = compare_reports({"rollouts": [with_outcome[r.key] for r in done_a]},
                             {"rollouts": [with_outcome[r.key] for r in done_b]})
    pair_of = {key_of[id(p["a"])]: (key_of[id(p["b"])], p["delta_rmse_deg"], p["delta_time_aligned_drift_deg"])
               for p in result["pairs"]}
    waiting = sum(r.pending for r in side_a + side_b)
    return Comparison(q.compare_with, result, pair_of, waiting)


def comparison_html(c: Comparison) -> str:
    """Who wins, over the pairs: the compare command's summary in a few lines."""
    s, d = c.result["summary"], c.result["time_aligned_drift"]
    by_tag = sum(p["paired_by"] == "tag" for p in c.result["pairs"])

    def num(v: float | None, fmt: str) -> str:
        return "–" if v is None else format(v, fmt)

    lines = [f"<b>A</b>: the table's rows · <b>B</b>: session <b>{escape(c.session_b)}</b> · "
             f"{s['n_pairs']} pair(s) ({by_tag} by tag, {s['n_pairs'] - by_tag} by episode, start, prompt and kind)"]
    if s["n_compared"]:
        lines.append(f"RMSE: A better in {s['a_better']}, B better in {s['b_better']}, ties {s['ties']}; "
                     f"mean Δ (B − A) {num(s['mean_delta_rmse_deg'], '+.3f')} deg; "
                     f"Spearman {num(s['spearman_rmse'], '.2f')}; Wilcoxon p {num(s['wilcoxon_p'], '.3g')}")
    if d["n_compared"]:
        lines.append(f"time-aligned drift: A better in {d['a_better']}, B better in {d['b_better']}, "
                     f"ties {d['ties']}; mean Δ {num(d['mean_delta_deg'], '+.2f')} deg")
    for t in c.result.get("tests", []):  # is each difference real (inspector.report.significance)
        metric, verdict, detail = verdict_parts(t)
        lines.append(f"{escape(metric)}: <b>{escape(verdict)}</b> at 95%: {escape(detail)}")
    unpaired = [f"{len(c.result[f'unmatched_{side}'])} of {side.upper()}" for side in ("a", "b")
                if c.result[f"unmatched_{side}"]]
    if unpaired:
        lines.append("unpaired: " + ", ".join(unpaired))
    if c.waiting:
        lines.append(f"{c.waiting} row(s) still computing: the comparison grows as they arrive")
    return _scoped(f"<div class='ov-compare'>{'<br>'.join(lines)}</div>")


# ----------------------------------------------------------------------------------------------
# The table


def _scoped(inner: str) -> str:
    """HTML inside the overview's scope (where its styles apply)."""
    return f"<div class='{SCOPE}'>{inner}</div>"


def _f(value: float | None, fmt: str) -> str:
    return "–" if value is None else format(value, fmt)


@dataclass(frozen=True)
class _Column:
    header: str
    tip: str
    cell: Callable[[OverviewRow], str]
    numeric: bool = True
    css: str = ""


def _metric_cell(label: str, fmt: str) -> Callable[[OverviewRow], str]:
    return lambda r: "" if r.summary is None else _f(METRICS[label](r.summary), fmt)


def _seams_cell(r: OverviewRow) -> str:
    seams = r.summary.get("seams") if r.summary else None
    if not seams:
        return ""
    worst = (seams.get("worst") or {}).get("jump_deg")
    return f"{len(seams['flagged'])} ({_f(worst, '.1f')})" if seams["flagged"] else f"0 ({_f(worst, '.1f')})"


def _success_cell(success: bool | None) -> str:
    if success is None:
        return "–"
    return "<span style='color:#2b8a3e'>✓</span>" if success else "<span style='color:#c92a2a'>✗</span>"


def _columns(views: Sequence[str], notes: Mapping[str, Note], comparison: Comparison | None,
             many_sessions: bool, outcomes: bool = False, with_outcomes: bool = False) -> list[_Column]:
    def note_of(r: OverviewRow) -> Note:
        return notes.get(r.key, Note())

    def kind(r: OverviewRow) -> str:
        return KIND_LABELS.get(r.kind, r.kind)

    def episode(r: OverviewRow) -> str:
        s = r.summary
        return "" if s is None or s["episode_index"] is None else f"{s['episode_index']} @{s['start_frame']}"

    cols = [_Column("session", "session", lambda r: escape(r.session), False)] if many_sessions else []
    cols += [
        _Column("rollout", "rollout tag", lambda r: escape(r.tag), False, "tag"),
        _Column("kind", "single-chunk or autoregressive (AR)", kind, False),
        _Column("prompt", "the prompt", lambda r: f"<span title='{escape(r.prompt)}'>{escape(r.prompt)}</span>",
                False, "prompt"),
        _Column("episode", "GT episode @ start frame", episode, False),
    ]
    if with_outcomes:  # did the task succeed: label, file or simulation
        def outcome(r: OverviewRow) -> Mapping[str, Any]:
            return effective_of(r, notes) or {}

        cols += [_Column("success", "did the task succeed (the effective outcome)",
                         lambda r: _success_cell(outcome(r).get("success")), css="success"),
                 _Column("progress", "how far the task got [%]", lambda r: _f(outcome(r).get("progress"), ".0f"),
                         css="progress"),
                 _Column("failure", "how it failed", lambda r: escape(str(outcome(r).get("failure") or "")), False,
                         "failure"),
                 _Column("source", "where the outcome comes from: label, file, sim or recording",
                         lambda r: escape(str(outcome(r).get("source") or "")), False, "source")]
    if outcomes:  # a simulated evaluation: its summed reward
        cols += [_Column("reward", "summed reward of the episode", _metric_cell("reward", ".3g"), css="reward")]
    cols += [
        _Column("RMSE °", "chunk RMSE over steps and joints [deg]", _metric_cell("RMSE", ".3f"), css="rmse"),
        _Column("time-al. °", "time-aligned drift, mean over in-episode steps [deg]",
                _metric_cell("time-aligned mean", ".2f")),
        _Column("final °", "time-aligned drift at the last in-episode step [deg]",
                _metric_cell("time-aligned final", ".2f")),
        _Column("best-m. °", "best-match drift, mean [deg] (speed-invariant)", _metric_cell("best-match mean", ".2f")),
        _Column("final °", "best-match drift at the last in-episode step [deg]",
                _metric_cell("best-match final", ".2f")),
        _Column("tempo", "slope of matched GT time vs rollout time (1 = same speed)", _metric_cell("tempo", ".2f")),
        _Column("EE mm", "end-effector error, mean [mm]", _metric_cell("EE error", ".1f")),
        _Column("limit steps", "steps with any joint past its URDF limit (beyond the margin)",
                _metric_cell("limit steps", "d")),
        _Column("seams", "flagged chunk seams (chunk k+1 jumping from chunk k's last executed action) and the "
                "worst jump [deg]", _seams_cell, css="seams"),
        _Column("done s", "completion: when the arm reaches the GT's final pose and stays [s] (never: –)",
                _metric_cell("completion s", ".2f")),
        _Column("coupling °", "joint coherence: the worst of shoulder-elbow and elbow-wrist coupling error [deg]",
                _metric_cell("coupling", ".2f")),
        _Column("video break", "the first chunk from which the imagined video stays degraded (any view)",
                _metric_cell("video break", "d")),
    ]
    cols += [_Column(f"PSNR {v}", f"imagined vs GT frames, {v} camera [dB]",
                     cast(Callable[[OverviewRow], str],
                          lambda r, v=v: "" if r.summary is None else _f(r.summary["video_psnr_db"].get(v), ".1f")))
             for v in views]
    cols += [_Column(f"lag {v}", f"median lag, video GT time − joints GT time, {v} camera [s] "
                     "(+: the imagined video runs ahead of the predicted actions; frozen: the video stands "
                     "still while the joints move, no lag; no match: no frame has a GT time on both sides)",
                     cast(Callable[[OverviewRow], str], lambda r, v=v: "" if r.summary is None else median_lag_label(
                         (r.summary.get("video_action") or {}).get(v), missing="–")))
             for v in views]
    cols += [
        _Column("⚑", "flagged in the Notes", lambda r: "⚑" if note_of(r).flag else "", False, "flag"),
        _Column("note", "the rollout's note", lambda r: _note_cell(note_of(r).note), False, "note"),
    ]
    if comparison is not None:
        def pair(r: OverviewRow) -> tuple[str, float | None, float | None] | None:
            return comparison.pair_of.get(r.key)

        cols += [
            _Column("B", f"the paired rollout of {comparison.session_b}",
                    lambda r: escape(p[0].rsplit(" / ", 1)[-1]) if (p := pair(r)) else "", False, "tag"),
            _Column("Δ RMSE °", "RMSE of B minus RMSE of A [deg]: positive, B is worse",
                    lambda r: _delta_cell(p[1], ".3f") if (p := pair(r)) else "", css="delta"),
            _Column("Δ time-al. °", "time-aligned drift of B minus A [deg]",
                    lambda r: _delta_cell(p[2], ".2f") if (p := pair(r)) else ""),
        ]
    return cols


def _note_cell(note: str) -> str:
    if len(note) <= MAX_NOTE_CHARS:
        return escape(note)
    return f"<span title='{escape(note)}'>{escape(note[:MAX_NOTE_CHARS - 1])}…</span>"


def _delta_cell(delta: float | None, fmt: str) -> str:
    if delta is None:
        return "–"
    colour = "#c92a2a" if delta > 0 else "#2b8a3e" if delta < 0 else "inherit"
    return f"<span style='color:{colour}'>{delta:{'+' + fmt}}</span>"


def table_html(rows: Sequence[OverviewRow], shown: Sequence[OverviewRow], notes: Mapping[str, Note],
               comparison: Comparison | None = None, open_key: str | None = None) -> str:
    """The table of ``shown`` (the first :data:`MAX_TABLE_ROWS` of them); ``rows`` are all of
    them (they decide the PSNR columns). Each row carries its catalog key (``data-key``), each
    cell its column (``data-col``); the rollout open in the tab is marked."""
    views = views_of(rows)
    cols = _columns(views, notes, comparison, len({r.session for r in rows}) > 1,
                    outcomes=any(outcome_of(r) is not None for r in rows),
                    with_outcomes=any(effective_of(r, notes) is not None for r in rows))
    head = "".join(f"<th title='{escape(c.tip)}' data-col='{escape(c.css or c.header)}'"
                   f"{' class=num' if c.numeric else ''}>{escape(c.header)}</th>" for c in cols)
    body = []
    # a row without metrics: its text columns, then one cell across the rest (the error, or
    # that it is computing)
    n_text = next((i for i, c in enumerate(cols) if c.numeric), len(cols))
    for i, r in enumerate(shown[:MAX_TABLE_ROWS]):
        state = " error" if r.error else " pending" if r.pending else ""
        state += " open" if r.key == open_key else ""
        cells = [f"<td class='num idx'>{i + 1}</td>"]
        shown_cols = cols if r.summary is not None else cols[:n_text]
        cells += [f"<td data-col='{escape(c.css or c.header)}'{' class=num' if c.numeric else ''}>{c.cell(r)}</td>"
                  for c in shown_cols]
        if r.summary is None:
            cells.append(f"<td class='msg' colspan={len(cols) - n_text}>{escape(r.error or 'computing…')}</td>")
        body.append(f"<tr data-key='{escape(r.key)}' class='row{state}'>{''.join(cells)}</tr>")
    more = ""
    if len(shown) > MAX_TABLE_ROWS:
        more = (f"<div class='ov-more'>{MAX_TABLE_ROWS} of {len(shown)} rows shown: narrow them with "
                f"the search and filters, or sort to bring others up</div>")
    empty = "" if shown else "<div class='ov-more'>no rollout matches the filters</div>"
    return _scoped(f"<div class='ov-table-wrap'><table class='ov-table'><thead><tr><th class=num>#</th>{head}"
                   f"</tr></thead><tbody>{''.join(body)}</tbody></table>{empty}</div>{more}")


def header_html(rows: Sequence[OverviewRow], shown: Sequence[OverviewRow], n_cached: int) -> str:
    """Counts: rollouts, what is computed, what failed, what the filters keep."""
    n_err = sum(r.error is not None for r in rows)
    n_pending = sum(r.pending for r in rows)
    n_rows = len(rows) - n_err - n_pending
    parts = [f"<b>{len(rows)}</b> rollout(s)", f"{n_rows} with metrics ({n_cached} from the metrics cache)"]
    if n_pending:
        parts.append(f"<span class='busy'>{n_pending} computing…</span>")
    if n_err:
        parts.append(f"<span class='bad'>{n_err} could not be read</span>")
    parts.append(f"{len(shown)} match the filters")
    units = ("RMSE and drift in degrees (gripper 0..100 as is), end-effector error in mm, PSNR in dB; "
             "open a row with <i>Row to open</i> in the left panel")
    return _scoped(f"<div class='ov-head'>{' · '.join(parts)}<div class='ov-units'>{units}</div></div>")


# ----------------------------------------------------------------------------------------------
# Figures


# The app shows the drift figure first (autoregressive drift is what an evaluation looks at first),
# then the single-chunk figures side by side, then the six joint panels.
FIGURE_ORDER = ("drift", "per-step-rmse", "rmse-by-position", "joint-overlay")


def figures_html(shown: Sequence[OverviewRow]) -> str:
    """The HTML report's aggregate figures over the computed rows among ``shown``."""
    summaries = [r.summary for r in shown if r.summary is not None]
    if not summaries:
        return _scoped("<div class='ov-more'>figures appear once rows are computed</div>")
    figures = sorted(report_figures(summaries), key=lambda f: FIGURE_ORDER.index(f.key)
                     if f.key in FIGURE_ORDER else len(FIGURE_ORDER))
    return _scoped(f"<div class='ov-figure-grid'>{''.join(figure_html(f) for f in figures)}</div>")


# ----------------------------------------------------------------------------------------------
# Styles


# The table scrolls inside its own box (both ways); its rollout column stays in place when it
# scrolls sideways, so a row is still named in a window too narrow for every column.
_LAYOUT_CSS = """
.ov-head { font-size: 13px; color: #343a40; padding: 2px 2px 6px; }
.ov-head .busy { color: #e67700; } .ov-head .bad { color: #c92a2a; }
.ov-units { font-size: 11.5px; color: #6b7280; margin-top: 2px; }
.ov-compare { font-size: 12.5px; border: 1px solid #d0ebff; background: #f1f8ff; border-radius: 4px;
              padding: 5px 8px; margin: 0 0 6px; line-height: 1.45; }
.ov-table-wrap { max-height: 380px; overflow: auto; border: 1px solid #dee2e6; border-radius: 4px; }
.ov-table { border-collapse: collapse; font-size: 12.5px; font-variant-numeric: tabular-nums; width: 100%; }
.ov-table th, .ov-table td { padding: 3px 6px; border-bottom: 1px solid #f1f3f5; white-space: nowrap; text-align: left; }
.ov-table th { background: #f4f5f7; position: sticky; top: 0; z-index: 1; font-weight: 600; }
.ov-table .num { text-align: right; }
.ov-table td[data-col=prompt] { max-width: 180px; overflow: hidden; text-overflow: ellipsis; color: #495057; }
.ov-table td[data-col=note] { white-space: normal; max-width: 200px; color: #495057; }
.ov-table td[data-col=rmse] { font-weight: 600; }
.ov-table td.idx { color: #adb5bd; }
.ov-table td.msg { color: #868e96; font-style: italic; white-space: normal; }
.ov-table tr.error td.msg { color: #c92a2a; font-style: normal; }
.ov-table tr.open td { background: #fff4e6; }
.ov-table td[data-col=flag] { color: #e8590c; }
.ov-table td[data-col=tag], .ov-table th[data-col=tag] { position: sticky; left: 0; background: #fff; box-shadow: 1px 0 0 #dee2e6; }
.ov-table td[data-col=tag] { z-index: 1; }
.ov-table th[data-col=tag] { z-index: 2; background: #f4f5f7; }
.ov-table tr.open td[data-col=tag] { background: #fff4e6; }
.ov-more { font-size: 12px; color: #6b7280; padding: 4px 2px; }
.ov-figure-grid { display: grid; grid-template-columns: repeat(2, minmax(0, 1fr)); gap: 14px 22px; margin-top: 8px; }
.ov-figure-grid figure { margin: 0; }
.ov-figure-grid figure.wide { grid-column: 1 / -1; }
.ov-figure-grid h3 { font-size: 13.5px; margin: 0 0 2px; }
.ov-figure-grid .caption, .ov-figure-grid .note, .ov-figure-grid .panel-title { color: #6b7280; font-size: 11.5px; margin: 0 0 4px; }
.ov-figure-grid .note { font-style: italic; }
.ov-figure-grid .panels { display: grid; grid-template-columns: repeat(auto-fit, minmax(300px, 1fr)); gap: 4px 16px; }
.ov-figure-grid .panels.two { grid-template-columns: repeat(2, minmax(0, 1fr)); }
"""


def scoped_css(css: str, scope: str = SCOPE) -> str:
    """``css`` with every selector put under ``.scope`` (plain rule lists only: no @-rules, as
    ``chart.css`` is), so the overview's styles never reach the rest of the app."""
    css = re.sub(r"/\*.*?\*/", "", css, flags=re.S)
    out = []
    for selectors, body in re.findall(r"([^{}]+)\{([^{}]*)\}", css):
        scoped = ", ".join(f".{scope} {s.strip()}" for s in selectors.split(",") if s.strip())
        out.append(f"{scoped} {{{body.strip()}}}")
    return "\n".join(out)


def overview_css() -> str:
    """The overview's ``<style>``: the report's chart styles and the overview's layout, scoped."""
    chart = (resources.files("inspector.report") / "assets" / "chart.css").read_text(encoding="utf-8")
    return f"<style>{scoped_css(chart + _LAYOUT_CSS)}</style>"
