"""``inspector agreement``: does success judged in imagination rank checkpoints as reality does?

Rollouts are grouped by checkpoint (the session's model, see :func:`model_label`, renamed by
``--match``) and task (the prompt); a (checkpoint, task) with judged rollouts on both sides is one
point. The statistics across points are those of :mod:`inspector.stats.agreement`. Rollouts of
the same checkpoint from the same start (task, episode, start frame) on both sides are also paired
one to one, in tag order, for the confusion table of imagined against real success.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..data.session import Session
from ..errors import InspectorError
from ..stats.agreement import DEFAULT_BOOTSTRAP, MIN_POINTS, STATISTICS, Point, agreement, confusion
from .outcome_values import judged, model_label, open_sessions, session_outcomes, task_of

By = Literal["success", "progress"]
CONFIDENCE = 0.95


def _values(sessions: Sequence[Session], by: By, rename: Mapping[str, str], source: str | None) -> tuple[
        dict[tuple[str, str], list[float]], dict[tuple, list[bool]], int]:
    """``({(checkpoint, task): values}, {start: successes}, rollouts not judged)`` of one side."""
    cells: dict[tuple[str, str], list[float]] = defaultdict(list)
    starts: dict[tuple, list[bool]] = defaultdict(list)
    unjudged = 0
    for session in sessions:
        checkpoint = rename.get(model_label(session), model_label(session))
        outcomes = session_outcomes(session)
        for tag in sorted(session.rollouts):
            rollout = session.rollouts[tag]
            outcome = judged(outcomes, tag, rollout, source)
            value = outcome.progress if by == "progress" else outcome.success
            if value is None:
                unjudged += 1
                continue
            task = task_of(rollout)
            cells[(checkpoint, task)].append(float(value))
            if outcome.success is not None:
                starts[(checkpoint, task, rollout.episode_index, rollout.start_frame)].append(outcome.success)
    return cells, starts, unjudged


def build_agreement(imagined: Sequence[str | Path], real: Sequence[str | Path], *, by: By = "success",
                    match: Mapping[str, str] | None = None, imagined_source: str | None = None,
                    real_source: str | None = None, n_bootstrap: int = DEFAULT_BOOTSTRAP,
                    seed: int = 0) -> dict[str, Any]:
    """The agreement of the imagined evaluations with the real ones (see ``docs/metrics.md``).

    Args:
        imagined, real: session directories of each side.
        by: ``success`` (rate of successes) or ``progress`` (mean progress, 0..1).
        match: imagined checkpoint name -> real checkpoint name, where they differ.
        imagined_source, real_source: read only this outcome source on that side (``label``,
            ``file``, ``sim``, ``recording``; None: each rollout's effective outcome), so that one
            session can be both sides (a judge's file on its imagined video, its simulator's verdicts).

    Raises:
        InspectorError: a path is not a session; no checkpoint or no task in common; fewer than
            3 points judged on both sides.
    """
    imagined_cells, imagined_starts, imagined_unjudged = _values(open_sessions(imagined, "--imagined"), by, match or {},
                                                                 imagined_source)
    real_cells, real_starts, real_unjudged = _values(open_sessions(real, "--real"), by, {}, real_source)
    _check_common(imagined_cells, real_cells, by)
    keys = sorted(set(imagined_cells) & set(real_cells))
    if len(keys) < MIN_POINTS:
        raise InspectorError("--imagined/--real", f"{len(keys)} checkpoint-task point{'s' * (len(keys) != 1)} with "
                                                  f"{by} judged on both sides; the correlations need at least {MIN_POINTS}")
    points = [Point(c, t, np.array(imagined_cells[(c, t)]), np.array(real_cells[(c, t)])) for c, t in keys]
    stats = agreement(points, n_bootstrap=n_bootstrap, confidence=CONFIDENCE, seed=seed)
    pairs = [pair for start in sorted(set(imagined_starts) & set(real_starts), key=str)
             for pair in zip(imagined_starts[start], real_starts[start])]
    return {
        "by": by, "confidence": CONFIDENCE, "bootstrap": n_bootstrap,
        "sources": {"imagined": imagined_source or "effective", "real": real_source or "effective"},
        "points": [{"checkpoint": p.checkpoint, "task": p.task, "imagined": float(p.imagined.mean()),
                    "real": float(p.real.mean()), "imagined_rollouts": len(p.imagined), "real_rollouts": len(p.real)}
                   for p in points],
        "statistics": stats,
        "confusion": {**confusion(pairs), "pairs": len(pairs)},
        "unjudged": {"imagined": imagined_unjudged, "real": real_unjudged},
        "only_imagined": [list(k) for k in sorted(set(imagined_cells) - set(real_cells))],
        "only_real": [list(k) for k in sorted(set(real_cells) - set(imagined_cells))],
    }


def _check_common(imagined: Mapping[tuple[str, str], Any], real: Mapping[tuple[str, str], Any], by: By) -> None:
    for side, cells in (("--imagined", imagined), ("--real", real)):
        if not cells:
            raise InspectorError(side, f"no rollout has a judged {by} (an outcome with "
                                       f"{'success' if by == 'success' else 'progress'})")
    checkpoints = ({c for c, _ in imagined}, {c for c, _ in real})
    if not checkpoints[0] & checkpoints[1]:
        raise InspectorError("--imagined/--real", f"no checkpoint in common (imagined: {sorted(checkpoints[0])}; "
                                                  f"real: {sorted(checkpoints[1])}); rename with --match IMAGINED=REAL")
    tasks = ({t for _, t in imagined}, {t for _, t in real})
    if not tasks[0] & tasks[1]:
        raise InspectorError("--imagined/--real", f"no task (prompt) in common (imagined: {sorted(tasks[0])}; "
                                                  f"real: {sorted(tasks[1])})")


def measured_coverage_note(s: dict[str, Any]) -> str:
    """Beside an interval, its coverage as simulated, not as claimed (docs/ranking.md)."""
    coverage = s.get("measured_coverage")
    return "" if coverage is None else f"  (held the truth in >= {coverage:.0%} of simulated evaluations)"


_NAMES = {"pearson": "Pearson r", "spearman": "Spearman rho", "kendall": "Kendall tau", "mmrv": "MMRV",
          "mean_abs_difference": "mean |imagined - real|"}


def format_agreement(result: dict[str, Any]) -> str:
    what = "success rate" if result["by"] == "success" else "mean progress"
    lines = [f"{len(result['points'])} checkpoint-task points, {what} imagined vs real "
             f"({result['confidence']:.0%} bootstrap intervals over rollouts, nominal; their measured coverage "
             "beside them, docs/ranking.md)"]
    for name in STATISTICS:
        s = result["statistics"][name]
        if s["value"] is None:
            lines.append(f"  {_NAMES[name]:<24} undefined (a side's values are all equal)")
        else:
            lines.append(f"  {_NAMES[name]:<24} {s['value']:+.3f}  [{s['low']:+.3f}, {s['high']:+.3f}]"
                         f"{measured_coverage_note(s)}")
    lines.append("")
    lines.append(f"{'checkpoint':<24} {'task':<32} {'imagined':>9} {'real':>9}  rollouts")
    for p in result["points"]:
        lines.append(f"{p['checkpoint'][:24]:<24} {p['task'][:32]:<32} {p['imagined']:>9.2f} {p['real']:>9.2f}  "
                     f"{p['imagined_rollouts']}/{p['real_rollouts']}")
    c = result["confusion"]
    if c["pairs"]:
        lines.append("")
        lines.append(f"rollouts from the same start on both sides: {c['pairs']}")
        lines.append(f"  imagined success, real success {c['imagined_success_real_success']:>5}   "
                     f"imagined success, real failure {c['imagined_success_real_failure']:>5}")
        lines.append(f"  imagined failure, real success {c['imagined_failure_real_success']:>5}   "
                     f"imagined failure, real failure {c['imagined_failure_real_failure']:>5}")
    for side in ("imagined", "real"):
        if result["unjudged"][side]:
            lines.append(f"({result['unjudged'][side]} {side} rollouts without a judged {result['by']}: left out)")
    return "\n".join(lines)
