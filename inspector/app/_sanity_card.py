"""The sanity measures of a rollout as rows of its card (see docs/metrics.md, Sanity measures)."""

from __future__ import annotations

from ..analysis.sanity import sanity_measures
from ..analysis.timeline import RolloutTimeline
from ..data.session import CHAINED_KINDS


def sanity_rows(tl: RolloutTimeline) -> list[tuple[str, str]]:
    """(name, value) rows: flagged seams, completion, joint coherence, video breaks (as far as
    the video metrics computed so far tell)."""
    m = sanity_measures(tl, tl.known_video_metrics())
    rows: list[tuple[str, str]] = []
    seams = m["seams"]
    if seams is not None:
        worst = seams["worst"]
        flagged = ", ".join(map(str, seams["flagged"])) or "none"
        rows.append(("chunk seams flagged", f"{flagged}" + (f" · worst {worst['jump_deg']:.1f}° at chunk {worst['chunk']}"
                                                            if worst else "")))
    elif tl.kind in CHAINED_KINDS and not tl.has_joints:
        rows.append(("chunk seams", "not measured: no predicted actions (video only)"))
    c = m["completion"]
    if c is not None:
        if c["time_s"] is None:
            rows.append(("completion", f"never (GT at {c['gt_time_s']} s)"))
        else:
            rows.append(("completion", f"{c['time_s']:.2f} s (GT {c['gt_time_s']} s){' · early' if c['early'] else ''}"
                                       f" · drift before {c['drift_before']:.1f}° / after {c['drift_after']:.1f}°"))
    j = m["joint_coherence"]
    if j is not None and j["coupling_error_deg"]:
        phase = ", ".join(f"{k} {j['phase_offset_steps'][k]:+d} steps" for k in j["out_of_phase"]) or "none"
        undetermined = ", ".join(j["phase_undetermined"])
        rows.append(("joint coherence", f"coupling worst {max(j['coupling_error_deg'].values()):.2f}° · "
                                        f"out of phase: {phase}" + (f" · lag not determined: {undetermined}" if undetermined else "")))
    if m["video_break"]:
        rows.append(("video break", ", ".join(f"{v} {'holds' if b is None else f'chunk {b}'}"
                                              for v, b in sorted(m["video_break"].items()))))
    return rows


def flagged_seam_steps(tl: RolloutTimeline) -> list[int]:
    """Steps where a flagged seam's chunk starts (the targets of the seam key)."""
    m = sanity_measures(tl, {})
    seams = m["seams"]
    if seams is None:
        return []
    return [int(min(tl.chunk_start_step[k], tl.n_steps - 1)) for k in seams["flagged"]]


SEAM_HEX = "#e8590c"
COMPLETION_HEX = "#2b8a3e"
VIDEO_BREAK_HEX = "#7048e8"


def sanity_marks(tl: RolloutTimeline) -> list[tuple[int, str, str]]:
    """``(step, label, color)`` where a flagged seam's chunk starts, the rollout completes and each
    view's imagined video breaks (as far as the video metrics computed so far tell), by step: what
    the timeline and the drift plot mark (the recording marks the same, see ..export.sanity_series)."""
    m = sanity_measures(tl, tl.known_video_metrics())
    last = tl.n_steps - 1
    marks: list[tuple[int, str, str]] = []
    if m["seams"] is not None:
        marks += [(int(min(tl.chunk_start_step[k], last)), "seam flagged", SEAM_HEX) for k in m["seams"]["flagged"]]
    c = m["completion"]
    if c is not None and c["step"] is not None:
        marks.append((int(min(c["step"], last)), "completes", COMPLETION_HEX))
    for view, b in sorted(m["video_break"].items()):
        if b is not None and b < tl.n_chunks:
            marks.append((int(min(tl.chunk_start_step[b], last)), f"{view} video breaks", VIDEO_BREAK_HEX))
    return sorted(marks)


def slider_marks(tl: RolloutTimeline, marks: list[tuple[int, str, str]]) -> tuple[tuple[int, str], ...]:
    """The chunk slider's marks: each mark's chunk and a short label (one per chunk, the first)."""
    short = {"seam flagged": "seam", "completes": "done"}
    by_chunk: dict[int, str] = {}
    for step, label, _ in marks:
        by_chunk.setdefault(int(tl.step_chunk[step]), short.get(label, "video"))
    return tuple(sorted(by_chunk.items()))
