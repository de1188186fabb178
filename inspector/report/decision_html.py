"""The pages of ``inspector rank --html`` and ``inspector agreement --html``: one self-contained
HTML file each (inline SVG, nothing fetched), a figure and the table behind it.

The figure is drawn at its own size (one SVG pixel a CSS pixel, narrower on a narrow window), so its
text is the table's size; every point is named on the figure itself: the ranking's by the session
at its tick, the agreement's by its colour (the checkpoint) and its shape (the task), both in the
legend. Table headers sit over their column: right over numbers, left over text.
"""

from __future__ import annotations

import datetime
import os
from html import escape
from pathlib import Path
from typing import Any

from .._files import mkstemp_sibling
from ..errors import InspectorError
from ..stats.agreement import STATISTICS
from .agreement import _NAMES
from .html import _asset, _version
from .svg import CHAR_PX, MARKERS, Axes, colour_class, legend_html

_MAX_WIDTH_PX = 1100  # the ranking figure's widest; past it, the sessions' names are slanted
_MAX_TICK_CHARS = 24  # longer session names are cut on the axis (whole in the point's tooltip)


def _short(name: str) -> str:
    """A session's name on the axis: a long one loses its middle, as checkpoints of one run differ at
    their ends (``dreamzero-so1…finetune-step-8000``)."""
    if len(name) <= _MAX_TICK_CHARS:
        return name
    head = (_MAX_TICK_CHARS - 1) // 3
    return name[:head] + "…" + name[-(_MAX_TICK_CHARS - 1 - head):]


def _slot_px(names: list[str]) -> int:
    """Room of one session on the ranking's axis [px]: its name, level, under its tick."""
    return max(120, round(max((len(n) for n in names), default=0) * CHAR_PX) + 16)


def ranking_figure(result: dict[str, Any]) -> str:
    """Each session's strength (or success rate) with its interval, best first, each at a tick
    named after it, as SVG."""
    bt = result["method"] == "bradley_terry"
    key = "strength" if bt else "success_rate"
    rows = [r for r in result["ranking"] if r[key] is not None]
    names = [_short(r["session"]) for r in rows]
    ax = Axes(x_label="session (best first)", y_label="Bradley-Terry strength [log odds]" if bt else "success rate",
              x_min=0.5, x_max=len(rows) + 0.5, y_min=None if bt else 0.0, y_max=None if bt else 1.0,
              width=min(_MAX_WIDTH_PX, max(420, 80 + _slot_px(names) * len(rows))), height=320,
              x_ticks=list(enumerate(names, 1)))
    for i, r in enumerate(rows, 1):
        ax.line([i, i], [r["low"], r["high"]], cls="c0", key=r["session"], title=f"{r['session']}: {r['low']:.2f} to {r['high']:.2f}")
    ax.points(list(range(1, len(rows) + 1)), [r[key] for r in rows], cls="c0",
              titles=[f"{r['session']} ({r['model']}): {r[key]:.3f}" for r in rows],
              keys=[r["session"] for r in rows], label=f"{'strength' if bt else 'success rate'}, 95% interval")
    return _sized(ax, ax.svg() + legend_html(ax.legend))


def agreement_figure(result: dict[str, Any]) -> str:
    """Imagined against real value, one dot per checkpoint-task (colour: the checkpoint, shape: the
    task, both named in the legend), the diagonal drawn, as SVG."""
    what = "success rate" if result["by"] == "success" else "mean progress"
    ax = Axes(x_label=f"imagined {what}", y_label=f"real {what}", x_min=0.0, x_max=1.0, y_min=0.0, y_max=1.0,
              width=440, height=420)
    ax.line([0.0, 1.0], [0.0, 1.0], cls="mean", label="imagined = real")
    points = result["points"]
    checkpoints = list(dict.fromkeys(p["checkpoint"] for p in points))
    tasks = list(dict.fromkeys(p["task"] for p in points))
    for p in points:
        ax.points([p["imagined"]], [p["real"]], cls=colour_class(checkpoints.index(p["checkpoint"])),
                  titles=[f"{p['checkpoint']} · {p['task']}: imagined {p['imagined']:.2f}, real {p['real']:.2f}"],
                  keys=[f"{p['checkpoint']}|{p['task']}"], marker=_task_marker(tasks.index(p["task"])))
    ax.legend += [(colour_class(i), name, "dot", None) for i, name in enumerate(checkpoints)]
    ax.legend += [("neutral", task, _task_marker(i), None) for i, task in enumerate(tasks)]
    return _sized(ax, ax.svg() + legend_html(ax.legend))


def _task_marker(i: int) -> str:
    return MARKERS[i % len(MARKERS)]


def _sized(ax: Axes, figure: str) -> str:
    """The figure at its own size at most: its text then is as large as the table's, not
    stretched to the window's width (the SVG shrinks with a narrower window)."""
    return f'<div class="fig-box" style="max-width: {ax.width}px">{figure}</div>'


def _page(title: str, figure: str, table: str) -> str:
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return ("<!DOCTYPE html>\n"
            '<html lang="en"><head><meta charset="utf-8">'
            "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; style-src 'unsafe-inline'\">"
            f"<title>{escape(title)}</title><style>{_asset('chart.css')}{_asset('report.css')}</style></head><body>"
            f"<h1>{escape(title)}</h1><p class=\"meta\">inspector {escape(_version())} &middot; {when}</p>"
            f'<figure class="fig" id="figure">{figure}</figure>'
            f"{table}</body></html>\n")


def _table(header: list[str], rows: list[list[str]], text_columns: tuple[int, ...] = (0,)) -> str:
    """A table in its own scrolling box, as wide as its columns need: the ``text_columns`` are text
    (left-aligned, header too), the others numbers (right-aligned, header too)."""
    def cls(col: int, tag: str) -> str:
        if col in text_columns:
            return " class=t" if tag == "td" else ""
        return " class=num" if tag == "th" else ""

    head = "".join(f"<th{cls(i, 'th')}>{escape(h)}</th>" for i, h in enumerate(header))
    body = "".join("<tr>" + "".join(f"<td{cls(i, 'td')}>{escape(c)}</td>" for i, c in enumerate(row)) + "</tr>"
                   for row in rows)
    return f'<div class="table-wrap fit"><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>'


def _interval(r: dict[str, Any], fmt: str) -> str:
    return "—" if r["low"] is None else f"[{format(r['low'], fmt)}, {format(r['high'], fmt)}]"


def render_ranking_html(result: dict[str, Any]) -> str:
    bt = result["method"] == "bradley_terry"
    key = "strength" if bt else "success_rate"
    rows = [[str(i), r["session"], r["model"], "—" if r[key] is None else f"{r[key]:+.3f}" if bt else f"{r[key]:.1%}",
             _interval(r, "+.3f" if bt else ".1%"),
             *([str(r["votes"]), f"{r['wins']:g}-{r['losses']:g}-{r['ties']}"] if bt
               else [f"{r['successes']}/{r['episodes']}"])]
            for i, r in enumerate(result["ranking"], 1)]
    table = _table(["#", "session", "model", "strength" if bt else "success rate", "95% interval",
                    *(["votes", "wins-losses-ties"] if bt else ["successes"])], rows, text_columns=(1, 2))
    if bt:
        m = result["win_matrix"]
        cells = [[name, *("—" if v == 0 else f"{w:g} of {v}" for w, v in zip(wins, votes))]
                 for name, wins, votes in zip(m["sessions"], m["wins"], m["votes"])]
        table += "<h2>Wins of row over column (ties as halves), of the votes between them</h2>"
        table += _table(["", *m["sessions"]], cells)
    return _page("Checkpoint ranking", f"<p class=\"caption\">{escape(result['note'])}</p>{ranking_figure(result)}", table)


def render_agreement_html(result: dict[str, Any]) -> str:
    stats = result["statistics"]
    rows = [[_NAMES[n], "undefined" if stats[n]["value"] is None else f"{stats[n]['value']:+.3f}",
             _interval(stats[n], "+.3f"),
             "—" if stats[n].get("measured_coverage") is None else f"{stats[n]['measured_coverage']:.0%}"]
            for n in STATISTICS]
    points = "<h2>Checkpoint-task points</h2>" + _table(
        ["checkpoint", "task", "imagined", "real", "rollouts imagined/real"],
        [[p["checkpoint"], p["task"], f"{p['imagined']:.2f}", f"{p['real']:.2f}",
          f"{p['imagined_rollouts']}/{p['real_rollouts']}"] for p in result["points"]], text_columns=(0, 1))
    caption = (f"<p class=\"caption\">{len(result['points'])} checkpoint-task points; "
               f"{result['confidence']:.0%} bootstrap intervals over rollouts; &ldquo;held the truth&rdquo;: "
               "the least share of simulated small evaluations in which such an interval held the statistic "
               "of the true rates.</p>")
    c = result["confusion"]
    confusion = ("" if not c["pairs"] else
                 f"<h2>Rollouts from the same start on both sides ({c['pairs']})</h2>"
                 + _table(["", "real success", "real failure"],
                          [["imagined success", str(c["imagined_success_real_success"]),
                            str(c["imagined_success_real_failure"])],
                           ["imagined failure", str(c["imagined_failure_real_success"]),
                            str(c["imagined_failure_real_failure"])]]))
    return _page("Imagined vs real", caption + agreement_figure(result),
                 "<h2>Statistics</h2>" + _table(["statistic", "value", "95% interval", "held the truth"], rows)
                 + points + confusion)


def _write(page: str, out: str | Path) -> Path:
    out = Path(out)
    if out.is_dir():
        raise InspectorError(out, "is a directory, expected an .html file to write")
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = mkstemp_sibling(out)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(page)
        os.replace(tmp, out)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise InspectorError(out, f"cannot write the page ({exc.strerror or exc})") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out


def write_ranking_html(result: dict[str, Any], out: str | Path) -> Path:
    return _write(render_ranking_html(result), out)


def write_agreement_html(result: dict[str, Any], out: str | Path) -> Path:
    return _write(render_agreement_html(result), out)
