"""Metrics for many rollouts of one episode at once (a checkpoint sweep, a seed study).

:func:`build_timeline` serves one rollout with everything the app draws; a sweep of hundreds of
rollouts against the same GT episode wants the same numbers without the per-rollout overhead,
so every metric here runs over a leading batch axis in one call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import torch

from . import metrics
from .kinematics import kinematics
from .units import Units, limits_in_units

Array = npt.NDArray[np.float64]


@dataclass
class SweepMetrics:
    """Per-rollout metrics of a batch of B rollouts with T executed steps each.

    Attributes:
        time_aligned_drift, best_match_drift, dtw_drift: (B, T).
        best_match_index: (B, T) GT frame each step matches.
        tempo: (B,).
        post_episode: (T,) steps past the episode's end (the same for every rollout).
        ee_error_mm: (B, T) tool-point distance to the time-aligned GT [mm].
        limit_violations: (B, 6) count per joint.
        chunk_rmse: (B, N) RMSE of each full chunk against GT over its horizon (NaN past the GT).
        rmse: (B,) over the chunks fully inside the GT.
    """

    time_aligned_drift: Array
    best_match_drift: Array
    best_match_index: npt.NDArray[np.int64]
    tempo: Array
    dtw_drift: Array
    dtw_cost: Array
    post_episode: npt.NDArray[np.bool_]
    ee_error_mm: Array
    limit_violations: npt.NDArray[np.int64]
    chunk_rmse: Array
    rmse: Array


def sweep_metrics(chunks: npt.ArrayLike, gt: npt.ArrayLike, units: Units = Units(),
                  executed_per_chunk: int = 9, offset: int = 0) -> SweepMetrics:
    """Every joint-space metric for B autoregressive rollouts of the same episode.

    Args:
        chunks: (B, N, H, 6) predicted chunks, dataset units.
        gt: (G, 6) GT joints of the episode, dataset units.
        units: the data's units.
        executed_per_chunk: actions executed from each chunk.
        offset: GT index of rollout step 0.
    """
    c = np.asarray(chunks, np.float64)
    gt = np.asarray(gt, np.float64)
    B, N, H, J = c.shape
    pred = c[:, :, :executed_per_chunk].reshape(B, -1, J)
    ta, gt_aligned, post = metrics.time_aligned(pred, gt, offset)
    bm, bm_index = metrics.best_match(pred, gt)
    tempo = metrics.tempo(bm_index, ~post)
    dtw_drift, dtw_cost = metrics.dtw(pred, gt[offset:])
    fk = kinematics()
    # float32: ~1e-4 mm at the SO-101's reach, and twice the throughput over B * T poses
    ee_pred = fk.gripper_positions(pred.reshape(-1, J), units, dtype=torch.float32).reshape(B, -1, 3)
    ee_gt = fk.gripper_positions(gt_aligned, units)
    ee_error = np.linalg.norm(ee_pred - ee_gt[None], axis=-1) * 1000.0
    limits = metrics.limit_violations(pred, limits_in_units(units)).sum(axis=1)
    starts = offset + np.arange(N) * executed_per_chunk
    inside = starts + H <= len(gt)
    chunk_rmse = np.full((B, N), np.nan)
    rmse = np.full(B, np.nan)
    if inside.any():
        gt_chunks = gt[starts[inside, None] + np.arange(H)[None]]  # (n_inside, H, 6)
        sq = (c[:, inside] - gt_chunks[None]) ** 2
        chunk_rmse[:, inside] = np.sqrt(sq.mean(axis=(2, 3)))
        rmse = np.sqrt(sq.mean(axis=(1, 2, 3)))
    return SweepMetrics(ta, bm, bm_index, np.asarray(tempo), dtw_drift, np.asarray(dtw_cost), post,
                        ee_error, limits, chunk_rmse, rmse)
