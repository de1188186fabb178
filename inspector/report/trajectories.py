"""What ``inspector report`` says about neural trajectories (GR00T-Dreams episodes), as lines:
their rows come from :mod:`inspector.rows.trajectories`.
"""

from __future__ import annotations

from typing import Any

from ..data.importers import GROOT_DREAMS as TRAJECTORY_LAYOUT

__all__ = ["TRAJECTORY_LAYOUT", "trajectory_table"]


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
