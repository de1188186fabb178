"""The step readout under the sliders, and the joint-limit texts the 3D scene labels joints with:
pure functions of a rollout's timeline and a step, so what a tab shows at a step is read without
a tab.
"""

from __future__ import annotations

from ..analysis.timeline import RolloutTimeline
from ..units import JOINT_NAMES
from ._cards import esc, unit


def limit_text(tl: RolloutTimeline, step: int) -> list[str]:
    """Per joint (JOINT_NAMES order), what the predicted pose at ``step`` does past a joint limit
    ("" where nothing): the 3D scene labels the joints with these, the readout lists them."""
    row = tl.limit_violation[step]
    if not row.any():
        return [""] * len(JOINT_NAMES)
    out = []
    for j, name in enumerate(JOINT_NAMES):
        if not row[j]:
            out.append("")
            continue
        v, (lo, hi) = tl.pred[step, j], tl.limits[j]
        u = "" if name == "gripper" or tl.units.arm != "degrees" else "°"
        out.append(f"⚠ {name} {v:.0f}{u} {'>' if v > hi else '<'} limit {hi if v > hi else lo:.0f}{u}")
    return out


def readout_html(tl: RolloutTimeline, step: int, lag: str) -> str:
    """The readout under the sliders at ``step``: its time and place (frame, or step, chunk and
    imagined frame), then what is wrong there (past the real episode's end, joints over their
    limits), the drift and the views' ``lag`` (:meth:`~._panels.PlotPanel.lag_text`)."""
    chunk = step // tl.steps_per_chunk
    notes = []
    if tl.post_episode is not None and tl.post_episode[step] or (
            tl.episode_end_step is not None and step >= tl.episode_end_step):
        notes.append("<span style='color:#c92a2a'>past the real episode's end</span>")
    over = [t for t in limit_text(tl, step) if t]
    if over:
        notes.append(f"<span style='color:#c92a2a'>{esc(' · '.join(over))}</span>")
    if tl.time_aligned_drift is not None:
        u = unit(tl)
        best = f" (best-match {tl.best_match_drift[step]:.1f}{u})" if tl.best_match_drift is not None else ""
        notes.append(f"{tl.labels.drift} {tl.time_aligned_drift[step]:.1f}{u}{best}")
    if lag:
        notes.append(esc(lag))
    if tl.kind == "episode":
        where = f"frame {step} / {tl.n_steps - 1}"
    else:
        where = (f"step {step} / {tl.n_steps - 1}"
                 + (f" · chunk {chunk} / {tl.n_chunks - 1}" if tl.n_chunks > 1 else "")
                 + (f" · imagined frame {tl.frame_index(step)}" if tl.rollout.views else ""))
    return (
        f"<div class='inspector-readout' data-step='{step}' style='font-size:0.78rem;line-height:1.4'>"
        f"t = <b>{tl.t_s[step]:.2f} s</b> · {where}"
        + (f"<br>{' · '.join(notes)}" if notes else "") + "</div>")
