"""The pages of ``inspector rank --html`` and ``inspector agreement --html``: one self-contained
HTML file each (inline SVG, nothing fetched), a figure and the table behind it."""

from __future__ import annotations

import datetime
import os
from html import escape
from pathlib import Path
from typing import Any

from .._files import mkstemp_sibling
from ..analysis.agreement import STATISTICS
from ..errors import InspectorError
from .agreement import _NAMES
from .html import _asset, _version
from .svg import Axes, legend_html


def ranking_figure(result: dict[str, Any]) -> str:
    """Each session's strength (or success rate) with its interval, best first, as SVG."""
    bt = result["method"] == "bradley_terry"
    key = "strength" if bt else "success_rate"
    rows = [r for r in result["ranking"] if r[key] is not None]
    ax = Axes(x_label="rank (best first)", y_label="Bradley-Terry strength [log odds]" if bt else "success rate",
              x_min=0.5, x_max=len(rows) + 0.5, y_min=None if bt else 0.0, y_max=None if bt else 1.0)
    for i, r in enumerate(rows, 1):
        ax.line([i, i], [r["low"], r["high"]], cls="c0", title=f"{r['session']}: {r['low']:.2f} to {r['high']:.2f}")
    ax.points(list(range(1, len(rows) + 1)), [r[key] for r in rows], cls="c0",
              titles=[f"{r['session']} ({r['model']}): {r[key]:.3f}" for r in rows],
              keys=[r["session"] for r in rows], label=f"{'strength' if bt else 'success rate'}, 95% interval")
    return ax.svg() + legend_html(ax.legend)


def agreement_figure(result: dict[str, Any]) -> str:
    """Imagined against real value, one dot per checkpoint-task, the diagonal drawn, as SVG."""
    what = "success rate" if result["by"] == "success" else "mean progress"
    ax = Axes(x_label=f"imagined {what}", y_label=f"real {what}", x_min=0.0, x_max=1.0, y_min=0.0, y_max=1.0,
              width=420, height=400)
    ax.line([0.0, 1.0], [0.0, 1.0], cls="mean", label="imagined = real")
    points = result["points"]
    ax.points([p["imagined"] for p in points], [p["real"] for p in points], cls="c0",
              titles=[f"{p['checkpoint']} · {p['task']}: imagined {p['imagined']:.2f}, real {p['real']:.2f}"
                      for p in points],
              keys=[f"{p['checkpoint']}|{p['task']}" for p in points], label="checkpoint-task")
    return ax.svg() + legend_html(ax.legend)


def _page(title: str, figure: str, table: str) -> str:
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return ("<!DOCTYPE html>\n"
            '<html lang="en"><head><meta charset="utf-8">'
            "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; style-src 'unsafe-inline'\">"
            f"<title>{escape(title)}</title><style>{_asset('chart.css')}{_asset('report.css')}</style></head><body>"
            f"<h1>{escape(title)}</h1><p class=\"meta\">inspector {escape(_version())} &middot; {when}</p>"
            f'<figure class="fig" id="figure">{figure}</figure>'
            f'<div class="table-wrap">{table}</div></body></html>\n')


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _interval(r: dict[str, Any], fmt: str) -> str:
    return "—" if r["low"] is None else f"[{format(r['low'], fmt)}, {format(r['high'], fmt)}]"


def render_ranking_html(result: dict[str, Any]) -> str:
    bt = result["method"] == "bradley_terry"
    key = "strength" if bt else "success_rate"
    rows = [[str(i), r["session"], r["model"], "—" if r[key] is None else f"{r[key]:+.3f}" if bt else f"{r[key]:.1%}",
             _interval(r, "+.3f" if bt else ".1%"),
             str(r["votes"]) if bt else f"{r['successes']}/{r['episodes']}"]
            for i, r in enumerate(result["ranking"], 1)]
    table = _table(["#", "session", "model", "strength" if bt else "success rate", "95% interval",
                    "votes" if bt else "successes"], rows)
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
             _interval(stats[n], "+.3f")] for n in STATISTICS]
    points = _table(["checkpoint", "task", "imagined", "real", "rollouts"],
                    [[p["checkpoint"], p["task"], f"{p['imagined']:.2f}", f"{p['real']:.2f}",
                      f"{p['imagined_rollouts']}/{p['real_rollouts']}"] for p in result["points"]])
    caption = (f"<p class=\"caption\">{len(result['points'])} checkpoint-task points; "
               f"{result['confidence']:.0%} bootstrap intervals over rollouts.</p>")
    c = result["confusion"]
    confusion = ("" if not c["pairs"] else
                 f"<h2>Rollouts from the same start on both sides ({c['pairs']})</h2>"
                 + _table(["", "real success", "real failure"],
                          [["imagined success", str(c["imagined_success_real_success"]),
                            str(c["imagined_success_real_failure"])],
                           ["imagined failure", str(c["imagined_failure_real_success"]),
                            str(c["imagined_failure_real_failure"])]]))
    return _page("Imagined vs real", caption + agreement_figure(result),
                 _table(["statistic", "value", "95% interval"], rows) + points + confusion)


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
