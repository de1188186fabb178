"""The sanity measures and the verdict of ``inspector report`` as text lines."""

from __future__ import annotations

from typing import Any

from .sanity import format_sanity


def _f(value: Any, fmt: str = ".2f") -> str:
    return "-" if value is None else format(value, fmt)


def sanity_lines(report: dict[str, Any]) -> list[str]:
    """A table of seams, completion, joint coherence and video breaks (rollouts that have any of
    them), the latents' silhouette, and the verdict table when the report carries one."""
    rows = [r for r in report["rollouts"] if r.get("seams") is not None or r.get("joint_coherence") is not None]
    lines: list[str] = []
    if rows:
        width = max([18] + [len(r["tag"]) for r in rows])
        lines += ["", "Sanity measures (seams: chunk k+1 jumping from chunk k's last executed action; jerk p95 "
                      "[deg/s^3] vs GT; completion [s] vs the GT's own; drift [deg] before / after completion)",
                  f"{'rollout':<{width}} {'seams flagged':>13} {'worst':>7} {'jerk p95':>9} {'GT':>8} "
                  f"{'done s':>7} {'GT s':>6} {'drift <':>7} {'drift >':>7} {'coupling':>8} "
                  f"{'out of phase':>14}  video break"]
        for r in rows:
            s, c, j = r.get("seams"), r.get("completion"), r.get("joint_coherence")
            flagged = "-" if s is None else (",".join(map(str, s["flagged"])) or "none")
            worst = s["worst"]["jump_deg"] if s and s["worst"] else None
            done = "never" if c is not None and c["time_s"] is None else _f(c and c["time_s"])
            coupling = max(j["coupling_error_deg"].values()) if j and j["coupling_error_deg"] else None
            phase = ",".join(f"{k}{j['phase_offset_steps'][k]:+d}" for k in j["out_of_phase"]) if j else "-"
            breaks = ", ".join(f"{v} {'holds' if b is None else f'chunk {b}'}"
                               for v, b in sorted((r.get("video_break") or {}).items())) or "-"
            lines.append(f"{r['tag']:<{width}} {flagged:>13} {_f(worst, '.1f'):>7} "
                         f"{_f(s and s['jerk_p95'], '.0f'):>9} {_f(s and s['gt_jerk_p95'], '.0f'):>8} "
                         f"{done:>7} {_f(c and c['gt_time_s']):>6} {_f(c and c['drift_before']):>7} "
                         f"{_f(c and c['drift_after']):>7} {_f(coupling):>8} {phase or 'none':>14}  {breaks}")
    latents = report.get("latents")
    if latents is not None:
        lines.append(f"Latents: silhouette {_f(latents.get('silhouette'), '.3f')} over {latents.get('n_vectors', 0)} "
                     f"vectors of {latents.get('n_episodes', 0)} episodes" + (f" ({latents['note']})" if latents.get("note") else ""))
    if report.get("sanity"):
        lines += [""] + format_sanity(report["sanity"])
    return lines
