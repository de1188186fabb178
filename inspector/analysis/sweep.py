"""Every joint-space metric for a batch of rollouts that share one GT episode, in one call.

This is the one place joint metrics are computed: a timeline is a batch of one
(:func:`inspector.analysis.timeline.build_timeline`), ``inspector report`` batches the rollouts of each
episode (a checkpoint sweep, a seed study), so hundreds of rollouts cost little more than one.
Each rollout's numbers never depend on which others share its batch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

from ..robot.kinematics import kinematics
from ..units import DEFAULT_LIMIT_MARGIN_DEG, Units, limit_margin_in_units, limits_in_units
from . import metrics

Array = npt.NDArray[np.float64]


@dataclass
class SweepMetrics:
    """Per-rollout metrics of a batch of B rollouts with T steps each (N chunks of horizon H).

    Joint values in the data's units. Without GT joints every GT field is None.

    Attributes:
        pred: (B, T, 6) the executed predicted joints.
        limits: (6, 2) joint limits; ``limit_margin``: (6,) tolerance past them, data units.
        limit_excess: (B, T, 6) distance past the limit (0 inside).
        limit_violation: (B, T, 6) past a limit by more than the margin.
        chunk_limit_violation: (B, N, H, 6) the same over every predicted chunk's horizon.
        limit_violations: (B, 6) joint-steps past a limit per joint.
        ee_pred: (B, T, 3) tool point [m].
        gt_aligned: (T, 6) GT at each step's time, clamped at the episode's end.
        post_episode: (T,) steps past the episode's end (the same for every rollout).
        time_aligned_drift, best_match_drift, dtw_drift: (B, T).
        best_match_index: (B, T) GT frame each step matches.
        tempo: (B,) NaN where fewer than two steps lie inside the episode.
        (best-match, tempo, the split and DTW are None without ``alignments``.)
        speed_mismatch, path_error: (B, T) time-aligned drift split (see ``metrics.drift_split``).
        dtw_cost: (B,).
        ee_gt: (T, 3) [m]; ee_error_mm: (B, T) tool-point distance to the time-aligned GT [mm].
        chunk_rmse: (B, N) RMSE of each chunk's horizon against GT (NaN past the GT).
        rmse: (B,), per_step_mse: (B, H), per_joint_rmse: (B, 6) over the chunks fully inside
            the GT (NaN when none is); ``chunks_inside``: (N,) which those are.
    """

    pred: Array
    limits: Array
    limit_margin: Array
    limit_excess: Array
    limit_violation: npt.NDArray[np.bool_]
    chunk_limit_violation: npt.NDArray[np.bool_]
    ee_pred: Array
    gt_aligned: Array | None = None
    post_episode: npt.NDArray[np.bool_] | None = None
    time_aligned_drift: Array | None = None
    best_match_drift: Array | None = None
    best_match_index: npt.NDArray[np.int64] | None = None
    tempo: Array | None = None
    speed_mismatch: Array | None = None
    path_error: Array | None = None
    dtw_drift: Array | None = None
    dtw_cost: Array | None = None
    ee_gt: Array | None = None
    ee_error_mm: Array | None = None
    chunk_rmse: Array | None = None
    chunks_inside: npt.NDArray[np.bool_] | None = None
    rmse: Array | None = None
    per_step_mse: Array | None = None
    per_joint_rmse: Array | None = None

    @property
    def limit_violations(self) -> npt.NDArray[np.int64]:
        return self.limit_violation.sum(axis=1)


def sweep_metrics(chunks: npt.ArrayLike, gt: npt.ArrayLike | None, units: Units = Units(),
                  executed_per_chunk: int = 9, offset: int = 0,
                  limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG, alignments: bool = True) -> SweepMetrics:
    """Every joint-space metric for B rollouts of the same episode.

    Args:
        chunks: (B, N, H, 6) predicted chunks, dataset units.
        gt: (G, 6) GT joints of the episode, dataset units, or None.
        units: the data's units.
        executed_per_chunk: timeline steps each chunk covers (the horizon for single chunks).
        offset: GT index of rollout step 0.
        limit_margin_deg: tolerance past a joint limit before it counts as a violation [deg].
        alignments: also align the paths (best-match, tempo, speed/path split, DTW); an episode's
            commanded vs measured arm runs on one clock, so its tracking error needs none.
    """
    c = np.asarray(chunks, np.float64)
    B, N, H, J = c.shape
    pred = c[:, :, :executed_per_chunk].reshape(B, -1, J)
    limits = limits_in_units(units)
    margin = limit_margin_in_units(units, limit_margin_deg)
    excess = metrics.limit_excess(pred, limits)
    out = SweepMetrics(
        pred=pred, limits=limits, limit_margin=margin, limit_excess=excess,
        limit_violation=excess > margin,
        chunk_limit_violation=metrics.limit_violations(c, limits, margin),
        ee_pred=cast(Array, kinematics().gripper_positions(pred, units)),  # float64 by default
    )
    if gt is None:
        return out
    gt = np.asarray(gt, np.float64)
    ta, gt_aligned, post = metrics.time_aligned(pred, gt, offset)
    out.gt_aligned, out.post_episode, out.time_aligned_drift = gt_aligned, post, ta
    if alignments:
        bm, bm_index = metrics.best_match(pred, gt, offset)
        out.best_match_drift, out.best_match_index = bm, bm_index
        out.tempo = np.asarray(metrics.tempo(bm_index, ~post), np.float64) if (~post).sum() >= 2 else np.full(B, np.nan)
        out.speed_mismatch, out.path_error = metrics.drift_split(ta, bm)
        out.dtw_drift, dtw_cost = metrics.dtw(pred, gt[offset:])
        out.dtw_cost = np.asarray(dtw_cost, np.float64)
    out.ee_gt = cast(Array, kinematics().gripper_positions(gt_aligned, units))  # float64 by default
    out.ee_error_mm = np.linalg.norm(out.ee_pred - out.ee_gt[None], axis=-1) * 1000.0

    # Each chunk's full horizon against GT over the same steps, where GT covers it.
    starts = offset + np.arange(N) * executed_per_chunk
    inside = starts + H <= len(gt)
    out.chunks_inside = inside
    out.chunk_rmse = np.full((B, N), np.nan)
    out.rmse, out.per_step_mse, out.per_joint_rmse = np.full(B, np.nan), np.full((B, H), np.nan), np.full((B, J), np.nan)
    if inside.any():
        gt_chunks = gt[starts[inside, None] + np.arange(H)[None]]  # (n_inside, H, 6)
        # (B, n_inside, H, 6), contiguous: the boolean index lays the batch axis innermost, and
        # numpy then sums each rollout in another order than alone (a last-bit difference that
        # would make a row depend on which rollouts shared its batch, i.e. on --jobs or --ray)
        sq = np.ascontiguousarray((c[:, inside] - gt_chunks[None]) ** 2)
        out.chunk_rmse[:, inside] = np.sqrt(sq.mean(axis=(2, 3)))
        out.rmse = np.sqrt(sq.mean(axis=(1, 2, 3)))
        out.per_step_mse = sq.mean(axis=(1, 3))
        out.per_joint_rmse = np.sqrt(sq.mean(axis=(1, 2)))
    return out
