"""``inspector report --html OUT.html``: the whole evaluation in one file that opens offline.

A report of LeRobot datasets (``report DATASET --html``) gets the same page for its episodes:
their tracking-error figures (:mod:`inspector.report.episode_figures`) and a table of episodes;
rollouts and episodes reported together each get their section.

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
import re
from collections.abc import Callable, Sequence
from html import escape
from importlib import resources
from pathlib import Path
from typing import Any, cast
from urllib.parse import quote

from .._files import mkstemp_sibling
from ..analysis.video_action import median_lag_label
from ..errors import InspectorError
from ..rows.rollout import limit_margin, limit_steps
from ..units import JOINT_NAMES
from .episode_figures import episode_figures, episode_key, episode_summary_numbers
from .figures import Figure, report_figures
from .html_outcomes import outcome_columns, success_section
from .overlay_frames import overlay_section
from .sanity_html import sanity_section
from .svg import legend_html

Row = dict[str, Any]
ASSETS = "assets"
# A rollout kind in a table's few characters.
KIND_LABELS = {"single_chunk": "single", "autoregressive": "AR", "open_loop_replay": "replay"}


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
        ("kind", "single-chunk, autoregressive or open-loop replay", False,
         lambda r: KIND_LABELS.get(r["kind"]) or str(r["kind"])),
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
         lambda r: _f(limit_steps(r), "d")),
    ]
    for view in views:
        cols.append((f"PSNR {view}", f"imagined vs GT frames, {view} camera [dB]", True,
                     cast(Callable[[Row], str], lambda r, v=view: _f(r["video_psnr_db"].get(v), ".1f"))))
    for view in views:
        cols.append((f"lag {view}", f"median lag, video GT time - joints GT time, {view} camera [s] "
                     "(+: the video runs ahead of the actions; frozen: the video stands still, no lag)", True,
                     cast(Callable[[Row], str],
                          lambda r, v=view: median_lag_label((r.get("video_action") or {}).get(v)))))
    cols += outcome_columns(rows)
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
        for header, _, num, cell in cols:
            cells.append(_cell(header, num, cell(r)))
        out.append(f'<tr data-key="{i}">{"".join(cells)}</tr>')
    out.append("</tbody></table>")
    return "".join(out)


# ----------------------------------------------------------------------------------------------
# Summary, figures, page


def _summary(report: dict[str, Any]) -> str:
    rows, agg = report["rollouts"], report["aggregate"]
    n_single = sum(r["kind"] == "single_chunk" for r in rows)
    with_limits = sum((limit_steps(r) or 0) > 0 for r in rows)
    n_replay = sum(r["kind"] == "open_loop_replay" for r in rows)
    kinds = f"{n_single} single-chunk, {len(rows) - n_single - n_replay} autoregressive" + (
        f", {n_replay} open-loop replay" if n_replay else "")
    cards = [(str(agg["n"]), f"rollouts ({kinds})"),
             (_f(agg["mean_rmse_deg"], ".3f"), "mean RMSE [deg]"),
             (_f(agg["median_rmse_deg"], ".3f"), "median RMSE [deg]"),
             (f'{_f(agg["best_rmse_deg"], ".3f")} / {_f(agg["worst_rmse_deg"], ".3f")}', "best / worst RMSE [deg]")]
    cards += [(f"{v:.2f}", f"mean PSNR {view} [dB]") for view, v in agg["mean_video_psnr_db"].items()]
    margin = limit_margin(rows)
    if margin is not None:  # a report of datasets alone, or of video-only rollouts, has none
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
    return "".join(out)


# An episode's key in ``errors`` is ``<dataset>/episode_<index>`` (inspector.data.episodes.episode_tag).
_EPISODE_ERROR_KEY = re.compile(r"/episode_\d+$")


def _errors(report: dict[str, Any]) -> str:
    """What could not be reported: rollouts and episodes, each with its error line."""
    errors = report.get("errors", {})
    out = []
    for what, keep in (("rollout", lambda k: not _EPISODE_ERROR_KEY.search(k)),
                       ("episode", lambda k: bool(_EPISODE_ERROR_KEY.search(k)))):
        items = [f"{escape(name)}: {escape(err)}" for name, err in errors.items() if keep(name)]
        if items:
            out.append(_details(f"{len(items)} {what}(s) not reported", items, "plain errors"))
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
    ("lag", "median over the imagined frames of the video's GT time (the GT frame each frame resembles most) "
            "minus the joints' GT time (their best match) [s]; + the video runs ahead of the actions. "
            "\"no match\": no frame has a GT time on both sides (the video matches no GT frame, or the "
            "joints are off the GT path)."),
    ("frozen", "the imagined video stands still while the joints move: over the frames with a lag, its GT "
               "time spans (10th to 90th percentile) less than a fifth of what the joints' GT time spans, "
               "and theirs at least 1 s. Its lag is no lag (each frame's is only how far the joints are "
               "from the one time the video shows), so none is given."),
    ("units", "the data's: arm joints in degrees, gripper 0..100."),
]


_DEFINITIONS += [
    ("success rate", "successes / rollouts with an outcome, per task and overall; the interval is the 95% Wilson "
                     "score interval (Wilson 1927)."),
    ("outcome", "success, progress [%], failure tag and source (label > file > sim/recording unless "
                "--outcome-source names one)."),
]

_EPISODE_DEFINITIONS = [
    ("tracking error", "|action - state| per frame: the commanded (leader) arm against the measured (follower) "
                       "arm; L2 over the 6 joints, or per joint (RMSE over the episode's frames)."),
    ("EE mm", "distance between the commanded and the measured arm's end effector (forward kinematics) [mm]."),
    ("lim.steps meas / cmd", "frames where the measured / commanded arm has a joint past its URDF limit "
                             "(beyond the margin)."),
]


def _episode_columns() -> list[tuple[str, str, bool, Callable[[Row], str]]]:
    """(header, tooltip, numeric, cell text) of each column of the episode table."""
    def track(field: str) -> Callable[[Row], str]:
        return lambda r: _f(r["tracking_error"][field], ".2f")

    def worst_joint(r: Row) -> str:
        rmse = r["tracking_error"].get("rmse")
        return "-" if not rmse else max(zip(rmse, JOINT_NAMES))[1]

    return [
        ("dataset", "dataset name", False, lambda r: str(r["dataset"])),
        ("ep", "episode index", True, lambda r: _f(r["episode_index"], "d")),
        ("frames", "frames in the episode", True, lambda r: _f(r["length"], "d")),
        ("s", "duration [s]", True, lambda r: _f(r["duration_s"], ".1f")),
        ("track mean", "tracking error, L2 over the joints, mean over frames [deg]", True, track("l2_mean")),
        ("max", "tracking error, L2 over the joints, max over frames [deg]", True, track("l2_max")),
        ("worst joint", "the joint with the largest tracking RMSE", False, worst_joint),
        ("worst RMSE", "that joint's tracking RMSE", True,
         lambda r: _f(max(r["tracking_error"].get("rmse") or [None], key=lambda v: -1 if v is None else v), ".2f")),
        ("EE mm", "end-effector tracking error, mean [mm]", True, lambda r: _f(r["ee_tracking_error_mm"]["mean"], ".1f")),
        ("lim.steps meas", "frames with a measured joint past its limit", True,
         lambda r: str(r["limit_violations"]["measured"]["steps"])),
        ("lim.steps cmd", "frames with a commanded joint past its limit", True,
         lambda r: str(r["limit_violations"]["commanded"]["steps"])),
        ("task", "the episode's task", False, lambda r: r["task"] or ""),
    ]


def _cell(header: str, numeric: bool, text: str) -> str:
    """A table cell: numbers align right (the default), text left; the long text column (a prompt,
    a task) takes the width the others leave, cut to one line, the whole of it in its tooltip."""
    if numeric:
        return f"<td>{escape(text)}</td>"
    if header in ("prompt", "task"):
        return f'<td class="t prompt" title="{escape(text)}">{escape(text)}</td>'
    return f"<td class=t>{escape(text)}</td>"


def _episode_table(rows: Sequence[Row]) -> str:
    cols = _episode_columns()
    head = "".join(f'<th{" class=num" if num else ""} title="{escape(tip)}">{escape(h)}</th>' for h, tip, num, _ in cols)
    out = [f'<table id="episodes"><thead><tr>{head}</tr></thead><tbody>']
    for i, r in enumerate(rows):
        cells = "".join(_cell(h, num, cell(r)) for h, _, num, cell in cols)
        out.append(f'<tr data-key="{episode_key(i)}">{cells}</tr>')
    out.append("</tbody></table>")
    return "".join(out)


def _trajectory_table(rows: Sequence[Row]) -> str:
    """Neural trajectories (no GT, so no drift): length, rate, steps past a limit, task, warnings."""
    head = "".join(f"<th>{h}</th>" for h in ("dataset", "episode", "steps", "fps", "steps past a limit",
                                               "calibration", "task", "warnings"))
    out = [f'<table id="trajectories"><thead><tr>{head}</tr></thead><tbody>']
    for r in rows:
        cells = (r["dataset"], r["episode_index"], r["length"], f"{r['fps']:g}", r["limit_violations"]["steps"],
                 r["calibration"], r["task"], "; ".join(r["warnings"]))
        out.append("<tr>" + "".join(f"<td>{escape(str(c))}</td>" for c in cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _episode_summary(rows: Sequence[Row]) -> str:
    n = episode_summary_numbers(rows)
    worst = n["worst"]
    cards = [(str(n["n"]), f"episodes ({n['frames']} frames)"),
             (_f(n["mean_l2"], ".2f"), "mean tracking error, L2 [deg]"),
             (f"{worst['tracking_error']['l2_mean']:.2f}", f"worst: {escape(str(worst['dataset']))} "
                                                           f"episode {worst['episode_index']} [deg]"),
             (str(n["past_limits"]), "episodes with the measured arm past a joint limit")]
    out = ['<div class="cards">']
    out += [f'<div class="card"><div class="v">{escape(v)}</div><div class="k">{k}</div></div>' for v, k in cards]
    out.append("</div>")
    return "".join(out)


def _table_tools(n: int, filter_id: str, shown_id: str, placeholder: str) -> str:
    return (f'<div class="table-tools"><input id="{filter_id}" type="search" placeholder="{escape(placeholder)}" '
            f'aria-label="filter rows"><span><span id="{shown_id}">{n}</span> of {n} shown; '
            f"click a header to sort</span></div>")


def render_report_html(report: dict[str, Any], title: str | None = None,
                       sources: Sequence[str] = (), rrd_links: dict[int, str] | None = None) -> str:
    """The page of a report (:func:`inspector.report.build.build_report`'s result) as one HTML string.

    Args:
        report: the report: its rollouts, its dataset episodes, or both (each gets its section).
        title: the page's heading (default: "Evaluation report", or "Dataset report" for
            episodes alone).
        sources: the paths the report was made from (shown under the heading).
        rrd_links: row index -> link of its ``.rrd`` (:func:`find_rrd_links`).

    Raises:
        ValueError: the report has no rollouts, episodes or neural trajectories (``build_report`` never
            returns such a report).
    """
    rows = report["rollouts"]
    episodes = report.get("episodes", [])
    trajectories = report.get("neural_trajectories", [])
    if not rows and not episodes and not trajectories:
        raise ValueError("a report without rollouts, episodes or neural trajectories has no page")
    title = title or ("Evaluation report" if rows else "Dataset report")
    links = rrd_links or {}
    when = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    what = []
    if rows:
        sessions = sorted({str(r.get("session")) for r in rows})
        what.append(f"{len(rows)} rollout(s) from session(s) {escape(', '.join(sessions))}")
    if episodes:
        datasets = list(dict.fromkeys(str(e["dataset"]) for e in episodes))
        what.append(f"{len(episodes)} episode(s) of dataset(s) {escape(', '.join(datasets))}")
    if trajectories:
        what.append(f"{len(trajectories)} neural trajector{'y' if len(trajectories) == 1 else 'ies'}")
    meta = (" and ".join(what) + (f" ({escape(', '.join(map(str, sources)))})" if sources else "")
            + f" &middot; inspector {escape(_version())} &middot; {when}")
    body = []
    if rows:
        figures = "".join(figure_html(f) for f in report_figures(rows))
        body.append(
            f"<h2>Summary</h2>{_summary(report)}{_errors(report)}{success_section(report['aggregate'])}"
            f'<h2>Figures</h2><div class="figures">{figures}</div>'
            f"<h2>Rollouts</h2>{_table_tools(len(rows), 'filter', 'shown', 'filter rows (tag, prompt, kind ...)')}"
            f'<div class="table-wrap">{_table(rows, links)}</div>'
            + sanity_section(report, figure_html) + overlay_section(report, sources))
    if episodes:
        figures = "".join(figure_html(f) for f in episode_figures(episodes))
        body.append(
            f"<h2>Dataset episodes</h2>{_episode_summary(episodes)}{_errors(report) if not rows else ''}"
            f'<div class="figures">{figures}</div>'
            f"<h2>Episodes</h2>{_table_tools(len(episodes), 'filter-episodes', 'shown-episodes', 'filter rows (task, dataset ...)')}"
            f'<div class="table-wrap">{_episode_table(episodes)}</div>')
    if trajectories:
        body.append(f"<h2>Neural trajectories</h2>{_errors(report) if not rows and not episodes else ''}"
                    f'<div class="table-wrap">{_trajectory_table(trajectories)}</div>')
    definitions = (_DEFINITIONS if rows else []) + (_EPISODE_DEFINITIONS if episodes else [])
    defs = "".join(f"<dt>{escape(k)}</dt><dd>{escape(v)}</dd>" for k, v in definitions)
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        # nothing may be fetched: inline styles and scripts only, no connections
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; "
        "style-src 'unsafe-inline'; script-src 'unsafe-inline'; img-src data:\">"
        f"<title>{escape(title)}</title><style>{_asset('chart.css')}{_asset('report.css')}</style></head><body>"
        f"<h1>{escape(title)}</h1><p class=\"meta\">{meta}</p>"
        + "".join(body) +
        f'<h2>Definitions</h2><dl class="defs">{defs}</dl>'
        f"<script>{_asset('report.js')}</script></body></html>\n")


def write_report_html(report: dict[str, Any], out: str | Path, sources: Sequence[str] = ()) -> Path:
    """Write the report's page to ``out`` (atomically), linking ``.rrd`` files found beside it."""
    out = Path(out)
    if out.is_dir():
        raise IsADirectoryError(21, "is a directory, expected an .html file to write", str(out))
    out.parent.mkdir(parents=True, exist_ok=True)
    page = render_report_html(report, sources=sources, rrd_links=find_rrd_links(report["rollouts"], out.parent))
    try:
        fd, tmp = mkstemp_sibling(out)  # readable as the umask allows, as every other output
    except OSError as exc:
        raise InspectorError(out, f"cannot write the page ({exc.strerror or exc})") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(page)
        os.replace(tmp, out)
    except OSError as exc:  # a full disk: the error names the page, not the temporary file
        Path(tmp).unlink(missing_ok=True)
        raise InspectorError(out, f"cannot write the page ({exc.strerror or exc})") from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out
