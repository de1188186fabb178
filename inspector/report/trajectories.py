"""What ``inspector report`` says about a neural trajectory (a GR00T-Dreams episode): no GT, so
no drift; its joints' ranges, its limit violations, its calibration and frame rate, its
``<DREAM>`` mark and any warning (a calibration that puts most steps past a limit).
"""

from __future__ import annotations

from typing import Any

from ..analysis.timeline import RolloutTimeline
from ..data.importers import GROOT_DREAMS as TRAJECTORY_LAYOUT
from ..units import JOINT_NAMES
from .rows import limit_record


def trajectory_summary(tl: RolloutTimeline) -> dict[str, Any]:
    """The JSON record of one neural trajectory (joints in degrees after calibration, gripper 0..100)."""
    r = tl.rollout
    source = r.extra.get("source", {})
    limits = tl.limit_summary()
    return {
        "layout": TRAJECTORY_LAYOUT,
        "dataset": r.session.name if r.session is not None else None,
        "episode_index": source.get("episode_index"),
        "task": r.prompt,
        "dream": bool(source.get("dream")),
        "length": tl.n_steps,
        "fps": tl.fps,
        "duration_s": tl.n_steps / tl.fps,
        "units": tl.units.label(),
        "calibration": (source.get("calibration") or {}).get("spec"),
        "views": list(r.views),
        "limit_violations": limit_record(limits, tl.limit_margin_deg),
        "joint_range": {j: [float(lo), float(hi)] for j, lo, hi in zip(JOINT_NAMES, tl.pred.min(axis=0),
                                                                         tl.pred.max(axis=0))},
        "raw_range": source.get("raw_range"),
        "warnings": list(r.extra.get("warnings", [])),
    }


def trajectory_table(rows: list[dict[str, Any]]) -> list[str]:
    """Neural trajectories as lines: length, steps past a limit and which joints, the mark, the task."""
    if not rows:
        return []
    width = max(12, *(len(str(e["dataset"])) for e in rows))
    lines = [f"Neural trajectories (IDM actions of generated videos, no GT; calibration {rows[0]['calibration']})",
             f"{'dataset':<{width}} {'ep':>5} {'steps':>5} {'fps':>5} {'lim.steps':>9} {'joints past a limit':<28} task"]
    for e in rows:
        lim = e["limit_violations"]
        joints = ", ".join(j for j, n in lim["by_joint"].items() if n) or "-"
        lines.append(f"{e['dataset']:<{width}} {e['episode_index']:>5} {e['length']:>5} {e['fps']:>5g} "
                     f"{lim['steps']:>9} {joints:<28} {e['task']}")
        lines += [f"  warning: {w}" for w in e["warnings"]]
    lines.append("")
    return lines
