"""The sanity section of the HTML page: the verdict table, the sanity measures per rollout, the
imagined videos' degradation curves and the latents' PCA coloured by episode.

Both tables fit the page's width: their long text (a verdict's figure and threshold, the joints out
of phase, the views' breaks) wraps in its cell instead of widening the page.
"""

from __future__ import annotations

from html import escape
from typing import Any

from .figures import Figure, Panel
from .svg import N_COLOURS, Axes, colour_class, series_style

Row = dict[str, Any]
# Rollouts whose degradation curves each get a colour and dash of their own, and a legend entry.
MAX_NAMED_LINES = 2 * N_COLOURS


def _f(value: Any, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def verdict_table(tests: list[dict[str, Any]], headline: str) -> str:
    rows = "".join(f'<tr class="verdict-{escape(t["verdict"].replace(" ", "-"))}"><td class=t>{escape(t["test"])}</td>'
                   f'<td class=t><b>{escape(t["verdict"])}</b></td><td class=t>{escape(t["figure"])}</td>'
                   f'<td class=t>{escape(t["threshold"])}</td></tr>' for t in tests)
    return (f'<p class="sanity-headline"><b>{escape(headline)}</b></p>'
            f'<div class="table-wrap"><table id="sanity" class="wrap"><thead><tr><th>test</th><th>verdict</th>'
            f'<th class="long">figure</th><th class="long">threshold</th></tr></thead><tbody>{rows}</tbody></table></div>')


def measures_table(rows: list[Row]) -> str:
    """One row per rollout with any sanity measure."""
    head = ["rollout", "seams flagged", "worst seam deg", "jerk p95", "GT jerk p95", "done s", "GT done s",
            "drift before", "drift after", "coupling deg", "out of phase", "video break"]
    out = [f'<table id="sanity-measures" class="wrap"><thead><tr>{"".join(f"<th>{escape(h)}</th>" for h in head)}</tr></thead><tbody>']
    for r in rows:
        s, c, j = r.get("seams"), r.get("completion"), r.get("joint_coherence")
        if s is None and j is None:
            continue
        coupling = max(j["coupling_error_deg"].values()) if j and j["coupling_error_deg"] else None
        cells = [r["tag"],
                 "-" if s is None else (", ".join(map(str, s["flagged"])) or "none"),
                 _f(s and s["worst"] and s["worst"]["jump_deg"], ".1f"),
                 _f(s and s["jerk_p95"], ".0f"), _f(s and s["gt_jerk_p95"], ".0f"),
                 "never" if c is not None and c["time_s"] is None else _f(c and c["time_s"], ".2f"),
                 _f(c and c["gt_time_s"], ".2f"), _f(c and c["drift_before"], ".2f"), _f(c and c["drift_after"], ".2f"),
                 _f(coupling, ".2f"),
                 ", ".join(f"{k} {j['phase_offset_steps'][k]:+d}" for k in j["out_of_phase"]) if j else "-",
                 ", ".join(f"{v} {'holds' if b is None else f'chunk {b}'}"
                           for v, b in sorted((r.get("video_break") or {}).items())) or "-"]
        out.append("<tr>" + "".join(f"<td class=t>{escape(str(x))}</td>" for x in cells) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def degradation_figure(rows: list[Row], keys: list[str] | None = None) -> Figure | None:
    """Per-chunk degradation of every chained rollout's imagined video, one panel per view, each
    rollout named in the legend (``keys``: each row's ``data-key``, linking its curves, its legend
    entry and its table row)."""
    views = sorted({v for r in rows for v in (r.get("video_degradation") or {})})
    if not views:
        return None
    keys = keys or [str(i) for i in range(len(rows))]
    named = len(rows) <= MAX_NAMED_LINES  # beyond, alike (each named by its tooltip and table row)
    fig = Figure("video-break", "Where the dream breaks",
                 "Degradation of the imagined video per chunk, no reference needed: the larger of the first "
                 "chunk's sharpness over this chunk's and this chunk's noise energy over the first's (1 = as "
                 "the start). The video breaks where it stays above 2 (the flat line).")
    for view in views:
        ax = Axes(x_label="chunk", y_label="degradation (x first chunk)", y_min=0)
        longest = max(len((r.get("video_degradation") or {}).get(view, {}).get("degradation", [])) for r in rows)
        ax.line([0, max(1, longest - 1)], [2.0, 2.0], "end", title="break threshold: 2x the first chunk")
        for i, r in enumerate(rows):
            d = (r.get("video_degradation") or {}).get(view)
            if d is None:
                continue
            curve = d["degradation"]
            ax.line(list(range(len(curve))), curve, series_style(i)[0] if named else "many", key=keys[i],
                    title=f"{r['tag']} {view}: break " + ("none" if d["break_chunk"] is None else f"chunk {d['break_chunk']}"))
        fig.panels.append(Panel(ax.svg(), view))
    fig.legend = [("end", "break threshold (2x the first chunk)", "dash", None)]
    if named:
        fig.legend += [(series_style(i)[0], r["tag"], series_style(i)[1], keys[i]) for i, r in enumerate(rows)]
    else:
        fig.legend.append(("many", "each rollout", "line", None))
    return fig


def latents_figure(latents: dict[str, Any] | None) -> Figure | None:
    """The latents' first two principal components, one colour per episode."""
    if not latents or not latents.get("points"):
        return None
    episodes = sorted({str(p["episode"]) for p in latents["points"]})
    ratio = latents.get("explained_variance") or [0, 0]
    ax = Axes(x_label=f"PC1 ({100 * ratio[0]:.0f}%)", y_label=f"PC2 ({100 * ratio[1]:.0f}%)")
    for e_i, episode in enumerate(episodes):
        pts = [(xy, p["tag"]) for p in latents["points"] if str(p["episode"]) == episode for xy in p["xy"]]
        ax.points([xy[0] for xy, _ in pts], [xy[1] for xy, _ in pts], colour_class(e_i),
                  titles=[f"{tag} (episode {episode})" for _, tag in pts], label=f"episode {episode}")
    s = latents.get("silhouette")
    fig = Figure("latents", "Latent stability",
                 f"Latents of every chunk or sample on their first two principal components, coloured by episode; "
                 f"episode silhouette {_f(s, '.3f')}.")
    fig.panels.append(Panel(ax.svg()))
    fig.legend = ax.legend
    return fig


def sanity_section(report: dict[str, Any], figure_html) -> str:
    """The page's sanity section ('' when the report has nothing for it)."""
    rows = report["rollouts"]
    parts = []
    if report.get("sanity"):
        parts.append(verdict_table(report["sanity"], report.get("sanity_headline", "")))
    if any(r.get("seams") is not None or r.get("joint_coherence") is not None for r in rows):
        parts.append(f'<h3 class="sub">Measures per rollout</h3><div class="table-wrap">{measures_table(rows)}</div>')
    degrading = [i for i, r in enumerate(rows) if r.get("video_degradation")]
    figures = [f for f in (degradation_figure([rows[i] for i in degrading], [str(i) for i in degrading]),
                           latents_figure(report.get("latents"))) if f is not None]
    if figures:
        parts.append(f'<div class="figures">{"".join(figure_html(f) for f in figures)}</div>')
    return f"<h2>Sanity</h2>{''.join(parts)}" if parts else ""
