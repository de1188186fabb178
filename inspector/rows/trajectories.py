"""The report row of a neural trajectory (a GR00T-Dreams episode): no GT, so no drift; its
joints' ranges, its limit violations, its calibration and frame rate, its ``<DREAM>`` mark and any
warning (a calibration that puts most steps past a limit).
"""

from __future__ import annotations

from typing import Any

from ..analysis.timeline import RolloutTimeline
from ..data.importers import GROOT_DREAMS as TRAJECTORY_LAYOUT
from ..units import JOINT_NAMES
from .rollout import limit_record


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
