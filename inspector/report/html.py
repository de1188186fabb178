"""``inspector report --html OUT.html``: the whole evaluation in one file that opens offline.

Everything is inline: the stylesheets (``chart.css`` for the figures, shared with the app's
overview, and ``report.css``) and a small script (``assets/``), the figures as SVG
(:mod:`inspector.report.figures`), the table as HTML. Nothing is fetched from the network, and the
page reads fully without its script (which only sorts, filters and highlights). Rollouts exported
beside the page (``inspector export ... -o DIR`` writes ``DIR/<tag>.rrd``) are linked from their rows.

    OUT.html
    <tag>.rrd                  linked from the row of rollout <tag>
    <session>/<tag>.rrd        also found (several sessions with the same tags)
"""

from __future__ import annotations

import datetime
import os
import tempfile
from collections.abc import Callable, Sequence
from html import escape
from importlib import resources
from pathlib import Path
from typing import Any, cast
from urllib.parse import quote

from .figures import Figure, report_figures
from .svg import legend_html

Row = dict[str, Any]
ASSETS = "assets"


def _asset(name: str) -> str:
    return (resources.files("inspector.report") / ASSETS / name).read_text(encoding="utf-8")


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("inspector")
    except metadata.PackageNotFoundError:
        return "(not installed)"


def _f(value: Any, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def find_rrd_links(rows: Sequence[Row], out_dir: Path) -> dict[int, str]:
    """Row index -> relative link of its ``.rrd`` beside the page (see the module docstring)."""
    tags = [r["tag"] for r in rows]
    links = {}
    for i, r in enumerate(rows):
        candidates = [f"{r['session']}/{r['tag']}.rrd"] if r.get("session") else []
        if tags.count(r["tag"]) == 1:
            candidates.append(f"{r['tag']}.rrd")
        for rel in candidates:
            if (out_dir / rel).is_file():
                links[i] = quote(rel)
                break
    return links


# ----------------------------------------------------------------------------------------------
# Table


def _drift(name: str, field: str = "mean") -> Callable[[Row], str]:
    return lambda r: _f(r[name] and r[name][field], ".2f")


def _columns(rows: Sequence[Row], views: list[str]) -> list[tuple[str, str, bool, Callable[[Row], str]]]:
    """(header, tooltip, numeric, cell text) of each column."""
    cols: list[tuple[str, str, bool, Callable[[Row], str]]] = []
    if len({r.get("session") for r in rows}) > 1:
        cols.append(("session", "session name", False, lambda r: r.get("session") or "-"))
    cols += [
        ("kind", "single-chunk or autoregressive", False,
         lambda r: "single" if r["kind"] == "single_chunk" else "AR"),
        ("ep", "GT episode index", True, lambda r: _f(r["episode_index"], "d")),
        ("start", "start frame in the episode", True, lambda r: _f(r["start_frame"], "d")),
        ("chunks", "predicted chunks", True, lambda r: _f(r["n_chunks"], "d")),
        ("RMSE", "chunk RMSE over steps and joints [deg]", True, lambda r: _f(r["rmse_deg"], ".3f")),
        ("time-al.", "time-aligned drift, mean over in-episode steps", True, _drift("time_aligned_drift")),
        ("final", "time-aligned drift at the last in-episode step", True, _drift("time_aligned_drift", "final")),
        ("best-m.", "best-match drift, mean", True, _drift("best_match_drift")),
        ("DTW", "DTW drift, mean", True, _drift("dtw_drift")),
        ("tempo", "slope of matched GT time vs rollout time", True, lambda r: _f(r["tempo"], ".2f")),
        ("EE mm", "end-effector error, mean [mm]", True,
         lambda r: _f(r["ee_error_mm"] and r["ee_error_mm"]["mean"], ".1f")),
        ("post", "chunks starting after the episode's end", True, lambda r: _f(r["post_episode_chunks"], "d")),
        ("lim.steps", "steps with any joint past its URDF limit (beyond the margin)", True,
         lambda r: str(r["limit_violations"]["steps"])),
    ]
    for view in views:
        cols.append((f"PSNR {view}", f"imagined vs GT frames, {view} camera [dB]", True,
                     cast(Callable[[Row], str], lambda r, v=view: _f(r["video_psnr_db"].get(v), ".1f"))))
    for view in views:
        cols.append((f"lag {view}", f"median lag, video GT time - joints GT time, {view} camera [s] "
                     "(+: the video runs ahead of the actions)", True,
                     cast(Callable[[Row], str],
                          lambda r, v=view: _f(((r.get("video_action") or {}).get(v) or {}).get("lag_s_median"),
                                               "+.2f"))))
    cols += [
        ("worst", "the worst chunk (largest time-aligned drift, else limit excess)", True,
         lambda r: _f((r.get("worst_chunk") or {}).get("chunk"), "d")),
        ("prompt", "the prompt", False, lambda r: r["prompt"] or ""),
    ]
    return cols


def _table(rows: Sequence[Row], links: dict[int, str]) -> str:
    views = sorted({v for r in rows for v in r["video_psnr_db"]})
    cols = _columns(rows, views)
    head = ['<th title="rollout tag (link: its .rrd recording)">rollout</th>']
    head += [f'<th{" class=num" if num else ""} title="{escape(tip)}">{escape(h)}</th>' for h, tip, num, _ in cols]
    out = [f'<table id="rollouts"><thead><tr>{"".join(head)}</tr></thead><tbody>']
    for i, r in enumerate(rows):
        tag = escape(r["tag"])
        if i in links:
            tag = f'<a href="{escape(links[i])}" title="Rerun recording">{tag}</a>'
        cells = [f"<td class=t>{tag}</td>"]
        for header, _, num, cell in cols:  # numbers align right (the default), text left
            cls = "" if num else (' class="t prompt"' if header == "prompt" else " class=t")
            cells.append(f"<td{cls}>{escape(cell(r))}</td>")
        out.append(f'<tr data-key="{i}">{"".join(cells)}</tr>')
    out.append("</tbody></table>")
    return "".join(out)


# ----------------------------------------------------------------------------------------------
# Summary, figures, page


def _summary(report: dict[str, Any]) -> str:
    rows, agg = report["rollouts"], report["aggregate"]
    n_single = sum(r["kind"] == "single_chunk" for r in rows)
    with_limits = sum(r["limit_violations"]["steps"] > 0 for r in rows)
    cards = [(str(agg["n"]), f"rollouts ({n_single} single-chunk, {len(rows) - n_single} autoregressive)"),
             (_f(agg["mean_rmse_deg"], ".3f"), "mean RMSE [deg]"),
             (_f(agg["median_rmse_deg"], ".3f"), "median RMSE [deg]"),
             (f'{_f(agg["best_rmse_deg"], ".3f")} / {_f(agg["worst_rmse_deg"], ".3f")}', "best / worst RMSE [deg]")]
    cards += [(f"{v:.2f}", f"mean PSNR {view} [dB]") for view, v in agg["mean_video_psnr_db"].items()]
    margin = rows[0]["limit_violations"]["margin_deg"]
    cards.append((str(with_limits), f"rollouts past a joint limit (&gt; {margin:g} deg)"))
    out = ['<div class="cards">']
    out += [f'<div class="card"><div class="v">{escape(v)}</div><div class="k">{k}</div></div>' for v, k in cards]
    out.append("</div>")
    divergences = report.get("prompt_divergence", [])
    if divergences:
        collapsed = sum(p["collapse_chunk"] is not None for p in divergences)
        items = []
        for p in divergences:
            collapse = "never" if p["collapse_chunk"] is None else f"from chunk {p['collapse_chunk']}"
            items.append(f"{escape(p['a'])} vs {escape(p['b'])}: mean {p['mean']:.2f}, max {p['max']:.2f}; "
                         f"paths indistinguishable {collapse}")
        out.append(_details(f"Prompt divergence: {len(divergences)} pair(s) from the same start, "
                            f"{collapsed} collapsing onto one path", items, "plain"))
    errors = report.get("errors", {})
    if errors:
        out.append(_details(f"{len(errors)} rollout(s) not reported",
                            [f"{escape(name)}: {escape(err)}" for name, err in errors.items()], "plain errors"))
    return "".join(out)


def _details(summary: str, items: list[str], cls: str, open_below: int = 10) -> str:
    """A list under a heading, folded when long."""
    state = " open" if len(items) < open_below else ""
    lis = "".join(f"<li>{item}</li>" for item in items)
    return f'<details{state}><summary>{escape(summary)}</summary><ul class="{cls}">{lis}</ul></details>'


def figure_html(fig: Figure) -> str:
    """A figure as HTML: heading, caption, its SVG panels and legend (styled by ``chart.css``)."""
    wide = " wide" if len(fig.panels) != 1 else ""
    out = [f'<figure id="{fig.key}" class="fig{wide}"><h3>{escape(fig.title)}</h3>'
           f'<p class="caption">{escape(fig.caption)}</p>']
    if fig.note:
        out.append(f'<p class="note">{escape(fig.note)}</p>')
    if fig.panels:
        out.append(f'<div class="panels{" two" if len(fig.panels) == 2 else ""}">')
        for panel in fig.panels:
            title = f'<p class="panel-title">{escape(panel.title)}</p>' if panel.title else ""
            out.append(f'<div class="panel">{title}{panel.svg}</div>')
        out.append("</div>" + legend_html(fig.legend))
    out.append("</figure>")
    return "".join(out)


_DEFINITIONS = [
    ("chunk RMSE", "sqrt(mean((pred - gt)^2)) over all steps and joints of a chunk; per-step MSE is the "
                   "mean over joints at each step (the DreamZero-SO101 metas' action_rmse_deg, per_step_mse)."),
    ("time-aligned drift", "d(pred(t), gt(min(t, T_end))), d the L2 norm over the 6 joints; samples past "
                           "the episode's end are post-episode and kept out of the means."),
    ("best-match drift", "min_j d(pred(t), gt_j) over every GT frame (speed-invariant); its argmin gives the tempo."),
    ("DTW drift", "order-preserving alignment of predicted and GT paths."),
    ("lim.steps", "steps with any joint more than the margin past its URDF limit."),
    ("units", "the data's: arm joints in degrees, gripper 0..100."),
]


def render_report_html(report: dict[str, Any], title: str = "Evaluation report",
                       sources: Sequence[str] = (), rrd_links: dict[int, str] | None = None) -> str:
    """The page of a report (:func:`inspector.report.build.build_report`'s result) as one HTML string.

    Args:
        report: the report.
        title: the page's heading.
        sources: the paths the report was made from (shown under the heading).
        rrd_links: row index -> link of its ``.rrd`` (:func:`find_rrd_links`).
    """
    rows = report["rollouts"]
    links = rrd_links or {}
    sessions = sorted({str(r.get("session")) for r in rows})
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    meta = (f"{len(rows)} rollout(s) from session(s) {escape(', '.join(sessions))}"
            + (f" ({escape(', '.join(map(str, sources)))})" if sources else "")
            + f" &middot; inspector {escape(_version())} &middot; {when}")
    figures = "".join(figure_html(f) for f in report_figures(rows))
    defs = "".join(f"<dt>{escape(k)}</dt><dd>{escape(v)}</dd>" for k, v in _DEFINITIONS)
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        # nothing may be fetched: inline styles and scripts only, no connections
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
        "style-src 'unsafe-inline'; script-src 'unsafe-inline'; img-src data:\">"
        f"<title>{escape(title)}</title><style>{_asset('chart.css')}{_asset('report.css')}</style></head><body>"
        f"<h1>{escape(title)}</h1><p class=\"meta\">{meta}</p>"
        f"<h2>Summary</h2>{_summary(report)}"
        f'<h2>Figures</h2><div class="figures">{figures}</div>'
        f'<h2>Rollouts</h2><div class="table-tools"><input id="filter" type="search" '
        f'placeholder="filter rows (tag, prompt, kind ...)" aria-label="filter rows">'
        f'<span><span id="shown">{len(rows)}</span> of {len(rows)} shown; click a header to sort</span></div>'
        f'<div class="table-wrap">{_table(rows, links)}</div>'
        f'<h2>Definitions</h2><dl class="defs">{defs}</dl>'
        f"<script>{_asset('report.js')}</script></body></html>\n")


def write_report_html(report: dict[str, Any], out: str | Path, sources: Sequence[str] = ()) -> Path:
    """Write the report's page to ``out`` (atomically), linking ``.rrd`` files found beside it."""
    out = Path(out)
    if out.is_dir():
        raise IsADirectoryError(21, "is a directory, expected an .html file to write", str(out))
    out.parent.mkdir(parents=True, exist_ok=True)
    page = render_report_html(report, sources=sources, rrd_links=find_rrd_links(report["rollouts"], out.parent))
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(page)
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out
