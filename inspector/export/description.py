"""The markdown a shared recording explains itself with: what the rollout is, its headline
metrics, and how to read the panels."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..analysis import metrics
from ..analysis.timeline import RolloutTimeline
from ..analysis.video_action import VideoAction, median_lag_label
from ..units import JOINT_NAMES


def describe(tl: RolloutTimeline, psnr_db: Mapping[str, float | None],
             agreements: Mapping[str, VideoAction] | None = None) -> str:
    """Markdown for ``/description``.

    Args:
        psnr_db: mean PSNR [dB] per view (None where the view has no GT frame).
        agreements: video-action agreement per view that has one.
    """
    if tl.kind == "episode":
        return describe_episode(tl)
    r = tl.rollout
    session = r.session
    model = dict(session.model) if session is not None else {}
    model_text = " / ".join(str(model[k]) for k in ("name", "checkpoint") if model.get(k)) or "not stated"
    unit = "deg" if tl.units.arm == "degrees" else "units"
    lines = [
        f"# Rollout `{r.tag}`",
        "",
        f"**Prompt:** {r.prompt or '(none)'}  ",
        f"**Model:** {model_text}  ",
        f"**Session:** {session.name if session is not None else '-'}  ",
        f"**Kind:** {r.kind}, {tl.n_chunks} chunk(s) x {tl.horizon} actions, "
        f"{tl.steps_per_chunk} executed per chunk, {tl.n_steps} steps at {tl.fps:g} fps "
        f"({tl.t_s[-1] + 1 / tl.fps:.2f} s)  ",
        f"**Units:** {tl.units.label()}  ",
        f"**Ground truth:** joints {tl.gt.source if tl.has_gt_joints else 'not available'}; "
        f"video {', '.join(tl.gt.views) or 'none'}"
        + (f"; episode {r.episode_index} from frame {r.start_frame}" if r.episode_index is not None else ""),
        "",
        "## Headline metrics",
        "",
        "| metric | value |",
        "|---|---|",
        *_joint_rows(tl, unit),
        *_limit_rows(tl),
        *[f"| mean video PSNR, {v} | {_fmt(p, ' dB')} |" for v, p in psnr_db.items()],
        *[_agreement_row(va) for va in (agreements or {}).values()],
        *_reference_rows(r.extra),
        *_outcome_rows(r.extra),
        *_fact_rows(r.extra),
        "",
        "## How to read this recording",
        "",
        "- **3D view:** the GT arm is opaque (yellow), the predicted arm translucent blue; the lines "
        "are the tool-point paths (orange GT, blue predicted), the light-blue trail the current "
        "chunk's whole predicted horizon, red dots where a joint is past its URDF limit.",
        "- **Videos:** each view's imagined frame next to the real (GT) frame at the same time.",
        "- **Timelines:** `time` (seconds since the start frame), `frame` (imagined frame), `chunk`. "
        "Scrub `chunk` to step chunk by chunk.",
        "- **Drift** is the joint-space distance `||pred - gt||` over the 6 joints, in data units. "
        "*Time-aligned* compares with GT at the same time; *best-match* with the nearest GT pose "
        "at any time (speed-invariant); *DTW* keeps the order of poses. Their difference splits "
        "drift into *speed mismatch* and *path error*.",
        "- **Markers:** grey triangles at y = 0 mark chunk starts, a red diamond the real "
        "episode's end (later steps compare with the final GT pose); red crosses in the joint "
        "plots mark limit violations. The `events` log lists the same moments.",
    ]
    if not tl.has_joints:
        lines.append("- **Video only:** this rollout has no joints (no predicted or executed arm): "
                     "there is no 3D view and no joint plot; the videos, their PSNR and the outcome are "
                     "what it holds.")
    elif not tl.has_gt_joints:
        lines.append("- No GT joints were available: drift plots and the GT arm are absent; "
                     "the prediction, its limits and the videos still are.")
    return "\n".join(lines) + "\n"


def describe_episode(tl: RolloutTimeline) -> str:
    """Markdown for the recording of a dataset episode: commanded (``action``) vs measured
    (``observation.state``) arm, how well the follower tracked its command."""
    r = tl.rollout
    unit = "deg" if tl.units.arm == "degrees" else "units"
    # an episode's timeline always has GT joints (the measured arm)
    assert tl.gt_aligned is not None and tl.time_aligned_drift is not None and tl.ee_error_mm is not None
    measured_excess = metrics.limit_excess(tl.gt_aligned, tl.limits)
    measured = metrics.LimitSummary.of(measured_excess > tl.limit_margin, measured_excess)
    commanded = tl.limit_summary()
    rmse = tl.chunk_errors.per_joint_rmse if tl.chunk_errors is not None else None
    lines = [
        f"# Episode {r.episode_index} of `{r.extra.get('dataset_name', '')}`",
        "",
        f"**Task:** {r.prompt or '(none)'}  ",
        f"**Length:** {tl.n_steps} frames at {tl.fps:g} fps ({tl.n_steps / tl.fps:.2f} s)  ",
        f"**Units:** {tl.units.label()}  ",
        f"**Cameras:** {', '.join(tl.gt.views) or 'none'}",
        "",
        "## Headline metrics",
        "",
        "| metric | value |",
        "|---|---|",
        f"| tracking error, mean / max | {_fmt(_mean(tl.time_aligned_drift))} / "
        f"{_fmt(float(tl.time_aligned_drift.max()))} {unit} |",
        *([f"| tracking RMSE, {j} | {_fmt(v, ' ' + unit, 2)} |" for j, v in zip(JOINT_NAMES, rmse)]
          if rmse is not None else []),
        f"| tool-point tracking error, mean / max | {_fmt(_mean(tl.ee_error_mm))} / "
        f"{_fmt(float(tl.ee_error_mm.max()))} mm |",
        f"| measured steps with a joint more than {tl.limit_margin_deg:g} deg past its limit | "
        f"{measured.steps} of {tl.n_steps} |",
        f"| commanded steps with a joint more than {tl.limit_margin_deg:g} deg past its limit | "
        f"{commanded.steps} of {tl.n_steps} |",
        "",
        "## How to read this recording",
        "",
        "- **3D view:** the measured arm (`observation.state`) is opaque, the commanded arm (`action`: "
        "on a leader-follower SO-101, the leader's position) translucent; the lines are their "
        "tool-point paths.",
        "- **Videos:** the episode's cameras.",
        "- **Tracking error** is `||action - state||` over the 6 joints at each frame, in data units; "
        "*joint error* the same per joint, signed. A follower lagging its leader shows as a steady "
        "error while moving.",
        "- **Markers:** red crosses in the joint plots mark commanded values past their limit.",
    ]
    return "\n".join(lines) + "\n"


def _joint_rows(tl: RolloutTimeline, unit: str) -> list[str]:
    if not tl.has_joints:
        return ["| joints | none: video only |"]
    if not tl.has_gt_joints:
        return ["| GT joints | not available |"]
    inside = ~tl.post_episode if tl.post_episode is not None else np.ones(tl.n_steps, bool)
    ta = tl.time_aligned_drift
    # with GT joints a rollout (not an episode) has every alignment
    assert ta is not None and tl.ee_error_mm is not None and tl.best_match_drift is not None and tl.dtw_drift is not None
    rows = [
        f"| chunk RMSE (chunks fully inside GT) | {_fmt(tl.chunk_errors.rmse if tl.chunk_errors else None, ' ' + unit)} |",
        f"| time-aligned drift, mean / final (in episode) | {_fmt(_mean(ta[inside]))} / "
        f"{_fmt(ta[inside][-1] if inside.any() else None)} {unit} |",
        f"| best-match drift, mean | {_fmt(_mean(tl.best_match_drift[inside]), ' ' + unit)} |",
        f"| DTW drift, mean | {_fmt(_mean(tl.dtw_drift), ' ' + unit)} |",
        f"| tempo (matched GT time / rollout time) | {_fmt(tl.tempo, '', 2)} |",
        f"| tool-point error, mean / final (in episode) | {_fmt(_mean(tl.ee_error_mm[inside]))} / "
        f"{_fmt(tl.ee_error_mm[inside][-1] if inside.any() else None)} mm |",
    ]
    if not inside.all():
        rows.append(f"| time-aligned drift after the episode, mean ({int((~inside).sum())} steps) | "
                    f"{_fmt(_mean(ta[~inside]), ' ' + unit)} |")
    return rows


def _agreement_row(va: VideoAction) -> str:
    """The median video-action lag of a view, or why it has none (a frozen video, no match)."""
    entry = va.summary()
    if entry["lag_s_median"] is None:  # frozen, no match, no GT joints: the note says which
        value = entry["note"] or median_lag_label(entry, missing="not measured")
    else:
        value = f"{median_lag_label(entry)} s ({100 * entry['matched_fraction']:.0f}% of frames matched"
        value += f", parting from chunk {entry['split_chunk']})" if entry["split_chunk"] is not None else ")"
    return f"| median video-action lag, {va.view} (video - joints GT time) | {value} |"


def _limit_rows(tl: RolloutTimeline) -> list[str]:
    if not tl.has_joints:
        return []
    per_joint = tl.limit_violation.sum(axis=0)
    steps = int(tl.limit_violation.any(axis=1).sum())
    detail = ", ".join(f"{j} {int(n)}" for j, n in zip(JOINT_NAMES, per_joint) if n) or "none"
    return [f"| steps with a joint past its limit | {steps} of {tl.n_steps} ({detail}) |"]


def _outcome_rows(extra: Mapping[str, object]) -> list[str]:
    """A simulated evaluation's verdict (lerobot-eval: success, reward, task)."""
    outcome = extra.get("outcome")
    if not isinstance(outcome, dict) or outcome.get("success") is None:
        return []
    reward = outcome.get("sum_reward")
    return [f"| outcome | {'success' if outcome['success'] else 'failure'}, reward "
            f"{'-' if reward is None else format(reward, '.3g')}, task {outcome.get('task')} |"]


def _fact_rows(extra: Mapping[str, object]) -> list[str]:
    """What the source's reader says about the rollout (``extra.facts``: name / text pairs, e.g. a
    neural trajectory's calibration and frame rate)."""
    facts = extra.get("facts") if isinstance(extra, Mapping) else None
    if not isinstance(facts, list):
        return []
    return [f"| {k} | {v} |" for k, v in (f for f in facts if isinstance(f, list) and len(f) == 2)]


def _reference_rows(extra: Mapping[str, object]) -> list[str]:
    """The source's own figures, each marked as such; a figure with a note (e.g. a mosaic
    sample's ``video_psnr_db``) carries it on its row."""
    ref = extra.get("reference_metrics") if isinstance(extra, Mapping) else None
    if not isinstance(ref, Mapping):
        return []
    notes = extra.get("reference_notes")
    notes = notes if isinstance(notes, Mapping) else {}
    rows = []
    for k, v in ref.items():
        if isinstance(v, (int, float, str)):
            note = notes.get(k)
            value = _fmt(v) if isinstance(v, (int, float)) else v
            rows.append(f"| {k} (as reported by the source) | {value}"
                        + (f" ({note})" if isinstance(note, str) else "") + " |")
    return rows


def _mean(values: np.ndarray) -> float | None:
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(v.mean()) if v.size else None


def _fmt(value: float | None, suffix: str = "", digits: int = 1) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.{digits}f}{suffix}"
