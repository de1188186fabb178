"""Chunk seams: the jump where one predicted chunk hands over to the next, and the jerk of the
executed actions.

A chunked policy executes the first ``E`` actions of chunk ``k``, then starts chunk ``k + 1`` from
its first action. The **seam jump** at chunk ``k + 1`` is ``chunks[k + 1, 0] - chunks[k, E - 1]``
per joint (data units) and its 6-joint norm; the GT's own step at that time,
``||gt(s) - gt(s - 1)||`` with ``s = (k + 1) E``, says how far the real arm moved there. A seam is
**flagged** when its jump exceeds ``max(SEAM_STEP_MULTIPLE x typical step, SEAM_FLOOR)``, the
typical step being the 95th percentile of the GT's per-step norm over the rollout's in-episode
steps (without GT joints: of the prediction's own steps inside its chunks).

**Jerk** is the third difference of the executed actions over time, ``fps^3 * diff(q, 3)``, as
its 6-joint norm [data units/s^3]; a rollout's figure is its 95th percentile, beside the GT's
over the same in-episode steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

SEAM_STEP_MULTIPLE = 2.0  # a seam jumps when it moves the arm twice the real arm's fastest steps at once
SEAM_FLOOR = 3.0  # ... and at least this much [deg]: a resting GT has steps near 0
JERK_PERCENTILE = 95.0


@dataclass
class Seams:
    """Every chunk boundary of a rollout (K = n_chunks - 1 seams).

    Attributes:
        chunk: (K,) the chunk ``k + 1`` whose first action follows chunk ``k``'s last executed one.
        jump: (K, 6) signed jump per joint, data units.
        jump_norm: (K,) its 6-joint norm.
        gt_step: (K,) the GT's own step norm at that time (NaN past the episode), or None.
        typical_step: the typical step the threshold multiplies.
        threshold: ``max(multiple x typical_step, floor)``.
        flagged: (K,) True where ``jump_norm > threshold``.
    """

    chunk: npt.NDArray[np.int64]
    jump: Array
    jump_norm: Array
    gt_step: Array | None
    typical_step: float
    threshold: float
    flagged: npt.NDArray[np.bool_]


def seam_jumps(chunks: npt.ArrayLike, executed_per_chunk: int, gt_aligned: npt.ArrayLike | None = None,
               in_episode: npt.ArrayLike | None = None, multiple: float = SEAM_STEP_MULTIPLE,
               floor: float = SEAM_FLOOR) -> Seams:
    """The seams of (N, H, 6) predicted chunks, each executing its first ``executed_per_chunk``.

    Args:
        chunks: finite values: a rollout without predicted actions (video only) has no seams, and
            its caller does not measure it (a jump from NaN would be written as a figure).
        gt_aligned: (T, 6) GT at each executed step (T = N * E), or None.
        in_episode: (T,) True for steps before the real episode's end (default: all).

    Raises:
        ValueError: ``chunks`` holds a non-finite value.
    """
    c = np.asarray(chunks, np.float64)
    if not np.isfinite(c).all():
        raise ValueError("seam_jumps: predicted actions with non-finite values have no seams to measure")
    e = executed_per_chunk
    n = c.shape[0]
    jump = c[1:, 0] - c[:-1, e - 1] if n > 1 else np.zeros((0, c.shape[-1]))
    norm = np.linalg.norm(jump, axis=-1)
    gt_step = None
    if gt_aligned is not None:
        g = np.asarray(gt_aligned, np.float64)
        inside = np.ones(len(g), bool) if in_episode is None else np.asarray(in_episode, bool)
        steps = np.linalg.norm(np.diff(g, axis=0), axis=-1)  # steps[s - 1]: from s - 1 to s
        steps_inside = steps[inside[1:]]
        typical = float(np.percentile(steps_inside, 95)) if steps_inside.size else 0.0
        at = np.arange(1, n) * e
        ok = at < len(g)
        gt_step = np.full(n - 1, np.nan)
        gt_step[ok] = np.where(inside[at[ok]], steps[at[ok] - 1], np.nan)
    else:
        own = np.linalg.norm(np.diff(c[:, :e], axis=1), axis=-1).ravel()
        typical = float(np.percentile(own, 95)) if own.size else 0.0
    threshold = max(multiple * typical, floor)
    return Seams(np.arange(1, n), jump, norm, gt_step, typical, threshold, norm > threshold)


def jerk(values: npt.ArrayLike, fps: float) -> Array:
    """(T - 3,) 6-joint norm of the third difference of (T, 6) values [data units/s^3]."""
    v = np.asarray(values, np.float64)
    if len(v) < 4:
        return np.zeros(0)
    return np.linalg.norm(np.diff(v, n=3, axis=0), axis=-1) * fps ** 3


def jerk_p95(values: npt.ArrayLike, fps: float) -> float | None:
    j = jerk(values, fps)
    return float(np.percentile(j, JERK_PERCENTILE)) if j.size else None


class SeamWorst(TypedDict):
    """The largest seam jump: the chunk it starts, its norm and per joint (data units), and the
    GT's own step there (null past the episode or without GT joints)."""

    chunk: int
    jump_deg: float
    gt_step_deg: float | None
    by_joint: list[float]


class FlaggedSeam(TypedDict):
    """A flagged seam: the chunk it starts, its jump's norm and the GT's own step there (data units)."""

    chunk: int
    jump_deg: float
    gt_step_deg: float | None


class SeamsJson(TypedDict):
    """The ``seams`` field of a report row: the flagged seams and the worst one in detail, not
    every seam's jump (a 60-chunk rollout has 59 seams; the recording and the app plot them all)."""

    flagged: list[int]
    flagged_jumps: list[FlaggedSeam]  # in the order of ``flagged``
    worst: SeamWorst | None
    n_seams: int
    threshold_deg: float
    typical_step_deg: float
    jerk_p95: float | None
    gt_jerk_p95: float | None


def seams_record(s: Seams, jerk_pred: float | None, jerk_gt: float | None) -> SeamsJson:
    def gt_step(i: int) -> float | None:
        return None if s.gt_step is None or not np.isfinite(s.gt_step[i]) else round(float(s.gt_step[i]), 4)

    worst: SeamWorst | None = None
    if len(s.jump_norm):
        i = int(np.argmax(s.jump_norm))
        worst = {"chunk": int(s.chunk[i]), "jump_deg": round(float(s.jump_norm[i]), 4), "gt_step_deg": gt_step(i),
                 "by_joint": [round(float(v), 4) for v in s.jump[i]]}
    flagged = np.flatnonzero(s.flagged)
    return {"flagged": [int(s.chunk[i]) for i in flagged],
            "flagged_jumps": [{"chunk": int(s.chunk[i]), "jump_deg": round(float(s.jump_norm[i]), 4),
                               "gt_step_deg": gt_step(int(i))} for i in flagged],
            "worst": worst, "n_seams": len(s.jump_norm),
            "threshold_deg": round(s.threshold, 4), "typical_step_deg": round(s.typical_step, 4),
            "jerk_p95": None if jerk_pred is None else round(jerk_pred, 3),
            "gt_jerk_p95": None if jerk_gt is None else round(jerk_gt, 3)}
