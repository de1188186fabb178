"""The figures of a dataset's episodes (``report DATASET``), from the episode rows alone.

- **tracking error per episode**: the follower's L2 tracking error |action - state| over the 6
  joints (mean and max per episode) and, beside it, the end-effector tracking error [mm];
- **per-joint tracking RMSE per episode**: which joint lags its command, episode by episode.

Episodes are placed at their index (x); several datasets are told apart by colour. A point's
``data-key`` is ``e<row>``: the HTML report links it to its row of the episode table (rollout
rows are keyed by their plain index).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..units import JOINT_NAMES
from .figures import Figure, Panel
from .svg import Axes, colour_class

Row = dict[str, Any]
# Episodes drawn as dots with tooltips; beyond, lines only (a page of 10,000 episodes stays small).
MAX_DOTS = 300


def episode_key(i: int) -> str:
    """The ``data-key`` of episode row ``i`` (the table row and its marks in the figures)."""
    return f"e{i}"


def _by_dataset(rows: Sequence[Row]) -> list[tuple[str, list[int]]]:
    """(dataset, row indexes sorted by episode index) per dataset, in the rows' order."""
    names = list(dict.fromkeys(str(r["dataset"]) for r in rows))
    return [(name, sorted((i for i, r in enumerate(rows) if str(r["dataset"]) == name),
                          key=lambda i: rows[i]["episode_index"])) for name in names]


def _series(ax: Axes, rows: Sequence[Row], idx: list[int], values: Sequence[float], cls: str,
            what: str, unit: str, label: str | None, style: str = "line") -> None:
    """One line over the episodes of ``idx`` (dots with tooltips when there are few)."""
    x = [rows[i]["episode_index"] for i in idx]
    ax.line(x, values, cls, label=label, style=style)
    if len(rows) <= MAX_DOTS:
        titles = [f"{rows[i]['dataset']} episode {rows[i]['episode_index']}: {what} {v:.2f} {unit}"
                  for i, v in zip(idx, values)]
        ax.points(x, values, cls, titles=titles, keys=[episode_key(i) for i in idx])


def tracking_figure(rows: Sequence[Row]) -> Figure:
    """Tracking error per episode: joint space (mean, max) and end effector (mean, max)."""
    fig = Figure("tracking-by-episode", "Tracking error per episode",
                 "The follower's tracking error |commanded action - measured state|: L2 over the 6 joints "
                 "[deg] and at the end effector [mm], mean (solid) and max (dashed) over each episode's frames.")
    groups = _by_dataset(rows)
    several = len(groups) > 1
    joint = Axes(x_label="episode", y_label="tracking error, L2 [deg]", y_min=0)
    ee = Axes(x_label="episode", y_label="end-effector error [mm]", y_min=0)
    for g, (name, idx) in enumerate(groups):
        cls = colour_class(g)
        for ax, field, unit, scale in ((joint, "tracking_error", "deg", ("l2_mean", "l2_max")),
                                       (ee, "ee_tracking_error_mm", "mm", ("mean", "max"))):
            mean = [rows[i][field][scale[0]] for i in idx]
            peak = [rows[i][field][scale[1]] for i in idx]
            _series(ax, rows, idx, mean, cls, "mean", unit, f"{name} mean" if several else "mean")
            _series(ax, rows, idx, peak, f"{cls} post", "max", unit, f"{name} max" if several else "max", "dash")
    fig.panels += [Panel(joint.svg(), "joints"), Panel(ee.svg(), "end effector")]
    fig.legend = joint.legend
    return fig


def joint_rmse_figure(rows: Sequence[Row]) -> Figure:
    """Per-joint tracking RMSE per episode, one line per joint."""
    fig = Figure("tracking-per-joint", "Per-joint tracking RMSE per episode",
                 "RMSE of action - state over each episode's frames, per joint [deg; gripper 0..100].")
    ax = Axes(x_label="episode", y_label="tracking RMSE [deg]", y_min=0)
    usable = [i for i, r in enumerate(rows) if r["tracking_error"].get("rmse")]
    for _, idx in _by_dataset(rows):
        idx = [i for i in idx if i in usable]
        for j, joint in enumerate(JOINT_NAMES):
            values = [rows[i]["tracking_error"]["rmse"][j] for i in idx]
            _series(ax, rows, idx, values, colour_class(j), f"{joint} RMSE", "", None)
    for j, joint in enumerate(JOINT_NAMES):
        ax.legend.append((colour_class(j), joint, "line", None))
    if usable:
        fig.panels.append(Panel(ax.svg()))
        fig.legend = ax.legend
    else:
        fig.note = "no episode with per-joint RMSE"
    return fig


def episode_figures(rows: Sequence[Row]) -> list[Figure]:
    """Every figure of a report's episode rows, in reading order."""
    if not rows:
        return []
    return [tracking_figure(rows), joint_rmse_figure(rows)]


def episode_summary_numbers(rows: Sequence[Row]) -> dict[str, Any]:
    """Headline numbers over the episode rows: count, frames, mean / worst tracking error."""
    l2 = np.array([r["tracking_error"]["l2_mean"] for r in rows], dtype=np.float64)
    worst = int(np.argmax(l2)) if len(rows) else None
    return {
        "n": len(rows),
        "frames": int(sum(r["length"] for r in rows)),
        "mean_l2": float(l2.mean()) if len(rows) else None,
        "worst": None if worst is None else rows[worst],
        "past_limits": sum(r["limit_violations"]["measured"]["steps"] > 0 for r in rows),
    }
