"""Completion: when the imagined arm reaches the real episode's final pose and stays there.

The **target** is the GT episode's last frame. A step is *at the target* when the predicted joints
lie within ``tol_deg`` of it (6-joint norm, data units) and the predicted tool point within
``tol_mm`` of the target's. The rollout **completes** at the first step from which it stays at the
target for ``hold_s`` seconds. The same rule on the GT itself gives the GT's own completion time,
so ``gt_time_s / time_s`` is the tempo of the whole task. Only arrivals after the arm has first
been away from the target count, away meaning farther than half the GT's own largest distance from
it (episodes start and end at one rest pose; a short detour near the start is no task done). Time-aligned drift is split at that
step: **before** completion and **after** it (the post-completion tail, past the episode's end
included: a model that never says "done" wanders there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import numpy as np
import numpy.typing as npt

COMPLETION_TOL_DEG = 6.0
COMPLETION_TOL_MM = 20.0
COMPLETION_HOLD_S = 0.5
# "away" from the target: farther than this fraction of the GT's own largest distance from it
AWAY_FRACTION = 0.5
# completion this much earlier than the GT's own (as a fraction of the GT's time) reads "early"
EARLY_FRACTION = 0.1


def completion_step(dist: npt.ArrayLike, ee_mm: npt.ArrayLike | None, tol_deg: float, tol_mm: float,
                    hold_steps: int, away_deg: float = 0.0) -> int | None:
    """First step, after the arm has first been away from the target (farther than
    ``max(tol_deg, away_deg)``), from which ``dist <= tol_deg`` (and ``ee_mm <= tol_mm``) for
    ``hold_steps`` steps in a row (the hold must fit in the series), or None. An arm that starts
    at its final pose (a rest pose both ends of an episode) has not completed anything until it
    has been away and come back."""
    d = np.asarray(dist, np.float64)
    at = d <= tol_deg
    if ee_mm is not None:
        at &= np.asarray(ee_mm, np.float64) <= tol_mm
    away = np.flatnonzero(d > max(tol_deg, away_deg))
    if away.size == 0:
        return None  # never left the target: no task done
    hold = max(1, int(hold_steps))
    start = int(away[0])
    if len(at) - start < hold:
        return None
    # runs of True of length >= hold: a window sum over the cumulative count
    c = np.r_[0, np.cumsum(at[start:])]
    full = (c[hold:] - c[:-hold]) == hold
    hits = np.flatnonzero(full)
    return int(hits[0]) + start if hits.size else None


class CompletionJson(TypedDict):
    """The ``completion`` field of a report row."""

    time_s: float | None
    step: int | None
    gt_time_s: float | None
    gt_duration_s: float
    tempo: float | None  # gt_time_s / time_s: 1 = the task's own tempo
    early: bool
    drift_before: float | None
    drift_after: float | None
    max_after_deg: float | None
    tol_deg: float
    tol_mm: float
    hold_s: float


@dataclass(frozen=True)
class CompletionTarget:
    """The GT side of completion, the same for every rollout from one GT episode and start (so
    computed once for them all: the GT's forward kinematics was half of completion's cost).

    Attributes:
        target: (6,) the GT episode's last frame; ee_target: (3,) its tool point [m].
        away_deg: how far "away" from the target is; hold: the hold time [steps].
        gt_step: the GT's own completion step (from the rollout's start), or None.
        gt_len: GT frames from the rollout's start to the episode's end.
    """

    target: npt.NDArray[np.float64]
    ee_target: npt.NDArray[np.float64]
    away_deg: float
    hold: int
    gt_step: int | None
    gt_len: int
    tol_deg: float
    tol_mm: float
    hold_s: float


def completion_target(gt_episode: npt.ArrayLike, ee_of, offset: int, fps: float,
                      tol_deg: float = COMPLETION_TOL_DEG, tol_mm: float = COMPLETION_TOL_MM,
                      hold_s: float = COMPLETION_HOLD_S) -> CompletionTarget:
    """The GT side of completion.

    Args:
        gt_episode: (G, 6) the whole GT episode; its last frame is the target.
        ee_of: ``ee_of(q (n, 6)) -> (n, 3)`` tool points [m] (forward kinematics in these units).
        offset: GT index of rollout step 0.
    """
    g = np.asarray(gt_episode, np.float64)
    target = g[-1]
    gt_part = g[offset:]
    # one forward-kinematics pass over the GT and its target together
    ee = np.asarray(ee_of(np.concatenate([gt_part, target[None]])), np.float64)
    ee_target = ee[-1]
    hold = int(round(hold_s * fps))
    gt_dist = np.linalg.norm(gt_part - target, axis=-1)
    away = AWAY_FRACTION * float(gt_dist.max()) if gt_dist.size else 0.0
    gt_ee_mm = np.linalg.norm(ee[:-1] - ee_target, axis=-1) * 1000.0
    gt_step = completion_step(gt_dist, gt_ee_mm, tol_deg, tol_mm, min(hold, len(gt_part)), away)
    return CompletionTarget(target, ee_target, away, hold, gt_step, len(gt_part), tol_deg, tol_mm, hold_s)


def completion_record(pred: npt.ArrayLike, ee_pred: npt.ArrayLike, gt: CompletionTarget,
                      drift: npt.ArrayLike, fps: float) -> CompletionJson:
    """Completion of a rollout.

    Args:
        pred: (T, 6) executed predicted joints; ee_pred: (T, 3) their tool point [m].
        gt: :func:`completion_target` of its GT episode and start.
        drift: (T,) time-aligned drift.
    """
    p = np.asarray(pred, np.float64)
    dist = np.linalg.norm(p - gt.target, axis=-1)
    ee_mm = np.linalg.norm(np.asarray(ee_pred, np.float64) - gt.ee_target, axis=-1) * 1000.0
    step = completion_step(dist, ee_mm, gt.tol_deg, gt.tol_mm, gt.hold, gt.away_deg)
    d = np.asarray(drift, np.float64)
    before = d if step is None else d[:step]
    after = None if step is None else d[step:]
    time_s = None if step is None else step / fps
    gt_time_s = None if gt.gt_step is None else gt.gt_step / fps
    tempo = None
    if time_s is not None and gt_time_s is not None and time_s > 0:
        tempo = round(gt_time_s / time_s, 4)
    early = bool(time_s is not None and gt_time_s is not None and time_s < (1 - EARLY_FRACTION) * gt_time_s)
    return {"time_s": _r(time_s), "step": step, "gt_time_s": _r(gt_time_s),
            "gt_duration_s": round(gt.gt_len / fps, 4), "tempo": tempo, "early": early,
            "drift_before": _r(float(before.mean())) if before.size else None,
            "drift_after": _r(float(after.mean())) if after is not None and after.size else None,
            "max_after_deg": _r(float(dist[step:].max())) if step is not None else None,
            "tol_deg": gt.tol_deg, "tol_mm": gt.tol_mm, "hold_s": gt.hold_s}


def _r(v: float | None) -> float | None:
    return None if v is None else round(float(v), 4)
