"""Drift metrics, exactly as docs/metrics.md defines them; vectorised, no loop over timesteps.

All joint-space figures are in the data's own units (arm degrees or -100..100, gripper 0..100):
``d(a, b) = ||a - b||_2`` over the 6 joints. Functions take a leading batch axis where it helps
(1,000 rollouts at once for a sweep) and plain (T, 6) arrays otherwise.
"""

from __future__ import annotations

import os
from collections.abc import Sized
from dataclasses import dataclass
from typing import cast

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


# ----------------------------------------------------------------------------------------------
# Chunk errors (the seed report's action_rmse_deg / per_step_mse / per_joint_rmse)


@dataclass
class ChunkErrors:
    """Errors of predicted chunks against GT over the same steps.

    Attributes:
        rmse: sqrt(mean((pred - gt)^2)) over every step and joint.
        per_step_mse: (H,) mean over joints (and chunks) per horizon step.
        per_joint_rmse: (6,) over steps (and chunks) per joint.
    """

    rmse: float
    per_step_mse: Array
    per_joint_rmse: Array


def chunk_errors(pred: npt.ArrayLike, gt: npt.ArrayLike) -> ChunkErrors:
    """Errors of (H, 6) or (N, H, 6) predicted chunks against GT of the same shape."""
    sq = (np.asarray(pred, np.float64) - np.asarray(gt, np.float64)) ** 2
    if sq.ndim == 2:
        sq = sq[None]
    return ChunkErrors(
        rmse=float(np.sqrt(sq.mean())),
        per_step_mse=sq.mean(axis=(0, 2)),
        per_joint_rmse=np.sqrt(sq.mean(axis=(0, 1))),
    )


def per_chunk_rmse(pred_chunks: npt.ArrayLike, gt_chunks: npt.ArrayLike) -> Array:
    """(N,) RMSE of each chunk: (N, H, 6) vs (N, H, 6)."""
    sq = (np.asarray(pred_chunks, np.float64) - np.asarray(gt_chunks, np.float64)) ** 2
    return np.sqrt(sq.mean(axis=(1, 2)))


# ----------------------------------------------------------------------------------------------
# Drift along a rollout


def joint_distance(a: npt.ArrayLike, b: npt.ArrayLike) -> Array:
    """``||a - b||_2`` over the last axis (the 6 joints)."""
    return np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=-1)


def time_aligned(pred: npt.ArrayLike, gt: npt.ArrayLike, offset: int = 0
                 ) -> tuple[Array, Array, npt.NDArray[np.bool_]]:
    """GT at the same time as each predicted sample, clamped at the episode's end.

    Args:
        pred: (..., T, 6) predicted joints, one per executed step.
        gt: (G, 6) GT joints of the episode.
        offset: GT index of rollout step 0 (the rollout's start frame).

    Returns:
        (drift, gt_aligned, post_episode): (..., T) ``d(pred(t), gt(min(offset + t, G - 1)))``,
        (T, 6) the GT used, and (T,) True where ``offset + t`` lies past the episode's end.
    """
    pred = np.asarray(pred, np.float64)
    gt = np.asarray(gt, np.float64)
    if len(gt) == 0:
        raise ValueError("time_aligned: the GT episode is empty")
    t = offset + np.arange(pred.shape[-2])
    idx = np.minimum(t, gt.shape[0] - 1)
    gt_aligned = gt[idx]
    return joint_distance(pred, gt_aligned), gt_aligned, t >= gt.shape[0]


# Distances a nearest-pose search holds at once (8 MiB of float64): a 60-chunk rollout against a
# long episode is searched in a few blocks, and a sweep of 1,000 rollouts never builds the whole
# (B, T, G) table.
NEAREST_BLOCK = 1 << 20
# From this many pose pairs (predicted poses times episode frames) on, a KD-tree answers sooner
# than the exhaustive search (5x at 8 million: 14 against 75 ms), so that a worker given the
# tasks of a report of hundreds of rollouts (32 rollouts of 540 steps against a 445-frame episode
# each) gains more than scipy.spatial's import costs it (0.7 s of CPU, once a process).
KDTREE_PAIRS = 5_000_000
# Threads a KD-tree query may use (-1: one per core); a pool's worker process sets 1, as for DTW:
# its own threads only crowd the other workers.
KDTREE_WORKERS = -1


def best_match(pred: npt.ArrayLike, gt: npt.ArrayLike, offset: int = 0) -> tuple[Array, npt.NDArray[np.int64]]:
    """Distance to the nearest GT pose anywhere in the episode (speed-invariant).

    Args:
        pred: (..., T, 6).
        gt: (G, 6).
        offset: GT index of rollout step 0. Where GT frames at different times tie (the rest
            pose at the episode's start and at its end), step t matches the one nearest in time
            to GT frame ``offset + t``.

    Returns:
        (drift, index): (..., T) ``min_j d(pred(t), gt_j)`` and its argmin j (the GT frame the
        arm "is at").
    """
    p = np.asarray(pred, np.float64)
    g = np.asarray(gt, np.float64)
    if len(g) == 0:
        raise ValueError("best_match: the GT episode is empty")
    steps = p.shape[-2] if p.ndim >= 2 else 1
    near = np.broadcast_to(offset + np.arange(steps), p.shape[:-1]).reshape(-1)
    drift, nearest = nearest_poses(p.reshape(-1, g.shape[1]), g, near)
    # A GT hold (the arm at rest) repeats one pose over many frames, and every frame of it ties;
    # an arbitrary one of them would bias the tempo fit, so each match moves to the middle of its run.
    index = _middle_of_identical_runs(g)[nearest]
    return drift.reshape(p.shape[:-1]), index.reshape(p.shape[:-1])


def nearest_poses(p: Array, g: Array, near: npt.NDArray[np.int64] | None = None) -> tuple[Array, npt.NDArray[np.int64]]:
    """For each row of ``p`` (N, D): the distance to its nearest row of ``g`` (G, D), exactly as
    ``sqrt(sum((p - g)^2))`` gives it, and that row's index: on a tie, the one closest to
    ``near`` (N,) of that row, else the first.

    One matrix product per block ranks the rows of ``g`` by ``|g|^2 - 2 p.g`` (the squared distance
    less ``|p|^2``, the same along a row). Its rounding can only swap rows within a few ulps of the
    best, so where more than one is that close, those are measured exactly. As quick as a KD-tree
    query at these sizes (thousands of poses of 6 joints), without scipy.spatial's import (0.7 s of
    CPU in every worker process that computes a row); from :data:`KDTREE_PAIRS` pairs on, a KD-tree
    gives the same answer sooner.
    """
    by_tree = len(g) > 1 and len(p) * len(g) >= KDTREE_PAIRS
    dist, index = (_nearest_by_tree if by_tree else _nearest_by_search)(p, g, near)
    far = ~np.isfinite(dist)
    dist[far], index[far] = np.inf, len(g) - 1
    return dist, index


def _nearest_by_tree(p: Array, g: Array, near: npt.NDArray[np.int64] | None) -> tuple[Array, npt.NDArray[np.int64]]:
    """:func:`nearest_poses` by a KD-tree over the distinct poses of ``g`` (its distances are the
    same sums). A pose held or revisited is one point of the tree, matched to its copy nearest in
    time; a row whose second nearest distinct pose is as near as its first is a tie, settled by the
    exhaustive search."""
    from scipy.spatial import cKDTree

    distinct, of_frame = np.unique(g, axis=0, return_inverse=True)
    of_frame = of_frame.reshape(-1)
    if len(distinct) == 1:
        return _nearest_by_search(p, g, near)
    found, pose = cKDTree(distinct).query(p, k=2, workers=KDTREE_WORKERS)
    dist, pose = found[:, 0].copy(), pose[:, 0]
    # the frames of each distinct pose, in time order: sorted keys (pose, frame)
    frames = np.argsort(of_frame, kind="stable")
    keys = of_frame[frames] * (len(g) + 1) + frames
    target = np.zeros(len(p), np.int64) if near is None else np.clip(near, 0, len(g))  # (none: the first copy)
    at = np.searchsorted(keys, pose * (len(g) + 1) + target)
    after, before = frames[np.minimum(at, len(g) - 1)], frames[np.maximum(at - 1, 0)]
    # the copy at or after the target and the one before it, where they show this pose: the nearer
    # in time, the earlier on a tie
    index = np.where(of_frame[after] == pose, after, before)
    closer = (of_frame[before] == pose) & (np.abs(before - target) <= np.abs(index - target))
    index = np.where(closer, before, index).astype(np.int64)
    tied = np.flatnonzero(~(found[:, 1] > found[:, 0]))  # two distinct poses as near (or non-finite)
    if len(tied):
        dist[tied], index[tied] = _nearest_by_search(p[tied], g, None if near is None else near[tied])
    return dist, index


def _nearest_by_search(p: Array, g: Array, near: npt.NDArray[np.int64] | None) -> tuple[Array, npt.NDArray[np.int64]]:
    """:func:`nearest_poses` by ranking every pose of ``g`` for every row of ``p``."""
    n, dims = p.shape
    g2 = np.einsum("ij,ij->i", g, g)
    slack_per_unit = 8 * dims * np.finfo(np.float64).eps  # bounds the product's rounding
    g2_max = g2.max(initial=0.0)
    dist = np.empty(n)
    index = np.empty(n, np.int64)
    step = max(1, NEAREST_BLOCK // len(g))
    with np.errstate(invalid="ignore", over="ignore"):  # (non-finite poses: an infinite distance)
        for s in range(0, n, step):
            block = p[s:s + step]
            ranked = block @ g.T
            ranked *= -2.0
            ranked += g2
            best = ranked.argmin(axis=1)
            slack = slack_per_unit * (np.einsum("ij,ij->i", block, block) + g2_max)
            close = ranked <= (ranked[np.arange(len(block)), best] + slack)[:, None]
            tied = np.flatnonzero(np.count_nonzero(close, axis=1) > 1)
            if len(tied):
                row, col = np.nonzero(close[tied])
                exact = np.square(block[tied[row]] - g[col]).sum(axis=1)
                apart = np.zeros_like(col) if near is None else np.abs(col - near[s + tied[row]])
                order = np.lexsort((col, apart, exact, row))  # per row: the nearest pose, then in time
                first = order[np.r_[True, row[order][1:] != row[order][:-1]]]
                best[tied[row[first]]] = col[first]
            dist[s:s + step] = np.sqrt(np.square(block - g[best]).sum(axis=1))
            index[s:s + step] = best
    return dist, index


def _middle_of_identical_runs(gt: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
    """(G,) for each GT frame, the middle frame of the run of identical poses it belongs to."""
    new_run = np.r_[True, np.any(gt[1:] != gt[:-1], axis=1)]
    run_id = np.cumsum(new_run) - 1
    starts = np.flatnonzero(new_run)
    ends = np.r_[starts[1:], len(gt)] - 1
    return ((starts + ends) // 2)[run_id]


def tempo(match_index: npt.ArrayLike, valid: npt.ArrayLike | None = None) -> Array | float:
    """Slope of matched GT time against rollout time: 1 = real speed, 0.8 = 20 % slow.

    A line fitted to ``match_index`` over the step number, robustly: the matched index jumps
    whenever the path passes a pose the episode visits twice (the rest pose at its start and its
    end), so after a least-squares fit the samples far off the line (beyond 3 robust standard
    deviations, and at least 3 frames) are dropped and the line refitted, three times.
    A prediction parked at one pose has tempo ~0.

    Args:
        match_index: (..., T) argmin indices from :func:`best_match`.
        valid: (T,) samples to fit (e.g. those before the episode's end).
    """
    j = np.asarray(match_index, np.float64)
    squeeze = j.ndim == 1
    j = j[None] if squeeze else j
    t = np.arange(j.shape[-1], dtype=np.float64)
    w = np.broadcast_to(np.ones_like(t) if valid is None else np.asarray(valid, np.float64), j.shape).copy()
    slope = np.full(j.shape[0], np.nan)
    for _ in range(4):
        n = w.sum(-1)
        ok = n >= 2
        tm = (w * t).sum(-1) / np.maximum(n, 1)
        jm = (w * j).sum(-1) / np.maximum(n, 1)
        dt = t - tm[:, None]
        var = (w * dt ** 2).sum(-1)
        slope = np.where(ok & (var > 0), (w * dt * (j - jm[:, None])).sum(-1) / np.where(var > 0, var, 1), np.nan)
        residual = np.abs(j - (jm[:, None] + slope[:, None] * dt))
        masked = np.where(w > 0, residual, np.nan)
        mad = np.nanmedian(masked, axis=-1) if np.isfinite(masked).any() else np.zeros(j.shape[0])
        keep = residual <= np.maximum(3 * 1.4826 * np.nan_to_num(mad), 3.0)[:, None]
        w = w * keep
    return float(slope[0]) if squeeze else slope


def drift_split(time_aligned_drift: npt.ArrayLike, best_match_drift: npt.ArrayLike) -> tuple[Array, Array]:
    """Split drift into (speed mismatch, path error).

    The path error is how far the arm is from *anywhere* on the real path (best-match); what the
    time-aligned drift adds on top is being at the wrong place along it, i.e. a tempo mismatch.
    """
    ta = np.asarray(time_aligned_drift, np.float64)
    bm = np.asarray(best_match_drift, np.float64)
    return np.maximum(ta - bm, 0.0), bm


def dtw(pred: npt.ArrayLike, gt: npt.ArrayLike) -> tuple[Array, Array | float]:
    """Order-preserving alignment (dynamic time warping) of predicted and GT paths.

    Unlike best-match, a prediction that visits the right poses in the wrong order pays for it.
    Both start together, but the alignment is open at the end: it ends at the GT frame the
    prediction's path reaches most cheaply, so a rollout that covers only part of the episode (a
    single chunk, a slow one) is not charged for the rest of it at its last steps.
    Rollouts are processed in blocks sized to a memory budget (:data:`DTW_BLOCK_BYTES`), one
    thread per core (numpy releases the GIL in the row operations).

    Args:
        pred: (..., T, 6).
        gt: (G, 6).

    Returns:
        (drift, cost): (..., T) mean distance of the GT samples aligned to each predicted sample,
        and (...,) total alignment cost divided by the path length.
    """
    from concurrent.futures import ThreadPoolExecutor

    p = np.ascontiguousarray(pred, np.float64)
    g = np.ascontiguousarray(gt, np.float64)
    if len(g) == 0:
        raise ValueError("dtw: the GT episode is empty")
    squeeze = p.ndim == 2
    if squeeze:
        p = p[None]
    lead = p.shape[:-2]
    p = p.reshape(-1, *p.shape[-2:])
    B, T, _ = p.shape
    workers = min(B, DTW_THREADS or os.cpu_count() or 1)
    by_memory = max(1, DTW_BLOCK_BYTES // max(1, 5 * T * len(g)))
    block = max(1, min(by_memory, -(-B // workers)))
    blocks = [p[i:i + block] for i in range(0, B, block)]
    with ThreadPoolExecutor(max_workers=max(1, min(len(blocks), workers))) as pool:
        results = list(pool.map(lambda b: _dtw_block(b, g), blocks))
    drift = np.concatenate([r[0] for r in results]).reshape(*lead, T)
    cost = np.concatenate([r[1] for r in results]).reshape(lead)
    return (drift[0], float(cost[0])) if squeeze else (drift, cost)


# Threads for DTW blocks (None: one per core); a worker process of a pool that already keeps
# every core busy sets 1.
DTW_THREADS: int | None = None

# Memory for one block of DTW tables [bytes]: 5 bytes per cell (float32 costs and a direction
# byte), so a 540-step rollout against a 600-frame episode takes 1.6 MB.
DTW_BLOCK_BYTES = 64 * 1024 * 1024

# A cell of the DTW direction table names its predecessor: bit 1 set = left, else bit 0 set = up,
# else the diagonal.
_UP_BIT, _LEFT_BIT = 1, 2


def _dtw_block(p: npt.NDArray[np.float64], g: npt.NDArray[np.float64]) -> tuple[Array, Array]:
    """DTW of a (B, T, 6) block against (G, 6), one vector operation per predicted step.

    Within a row, ``D[i, j] = min(a_j, c_ij + D[i, j-1])`` with ``a_j = c_ij + min(D[i-1, j-1],
    D[i-1, j])`` is a min-plus scan: with ``S`` the running sum of the row's costs,
    ``D[i, :] = S + cummin(a - S)``. So each row is a cumsum and a cummin, not a loop over j.
    Costs are float32, one small matrix product per rollout (so a rollout's path never depends
    on which others share its block); they only choose the path: each cell keeps the cheapest
    of its three predecessors (the diagonal first on ties, as textbook DTW does) and the
    backtrack measures the chosen cells exactly in float64.
    """
    B, T, _ = p.shape
    G = g.shape[0]
    centre = g.mean(axis=0)
    # absurd inputs (1e30 deg) would overflow float32 squares to inf: clip so that a squared
    # distance over 6 joints stays finite; the path is measured in float64 anyway
    limit = 1e18
    pc = np.clip(p - centre, -limit, limit).astype(np.float32)  # (B, T, 6)
    gc = np.clip(g - centre, -limit, limit).astype(np.float32)  # (G, 6)
    cost = np.empty((B, T, G), dtype=np.float32)
    for b in range(B):  # |p - g|^2 = |p|^2 + |g|^2 - 2 p.g
        np.matmul(pc[b], gc.T, out=cost[b])
    cost *= -2.0
    cost += (gc * gc).sum(-1)[None, None]
    cost += (pc * pc).sum(-1)[:, :, None]
    np.maximum(cost, 0.0, out=cost)
    np.sqrt(cost, out=cost)
    direction = np.empty((B, T, G), dtype=np.uint8)
    prev = np.full((B, G + 1), np.inf, dtype=np.float32)  # D[i-1, -1..G-1]; column -1 is the boundary
    prev[:, 0] = 0.0  # the origin: D[-1, -1] = 0
    row = np.empty((B, G + 1), dtype=np.float32)
    row[:, 0] = np.inf
    best_prev, a, running = (np.empty((B, G), dtype=np.float32) for _ in range(3))
    up, left = np.empty((B, G), dtype=bool), np.empty((B, G), dtype=bool)
    for i in range(T):
        c = cost[:, i]
        np.minimum(prev[:, :-1], prev[:, 1:], out=best_prev)
        np.less(prev[:, 1:], prev[:, :-1], out=up)  # up strictly cheaper than the diagonal
        np.add(best_prev, c, out=a)
        np.cumsum(c, axis=1, out=running)
        a -= running
        np.minimum.accumulate(a, axis=1, out=row[:, 1:])
        row[:, 1:] += running
        np.less(row[:, :-1], best_prev, out=left)  # left strictly cheaper than both
        d = direction[:, i]  # predecessor of each cell: bit 1 left, else bit 0 up, else diagonal
        np.add(left.view(np.uint8), left.view(np.uint8), out=d)
        np.bitwise_or(d, up.view(np.uint8), out=d)
        prev, row = row, prev
        row[:, 0] = np.inf  # D[i, -1]: only D[-1, -1] is the origin
    ends = np.argmin(prev[:, 1:], axis=1)  # open end: the cheapest D[T-1, j] (the earliest on a tie)
    drift, total, length = _dtw_backtrack(p, g, direction, ends)
    return drift, total / length


def _dtw_backtrack(p: npt.NDArray[np.float64], g: npt.NDArray[np.float64], direction: npt.NDArray[np.uint8],
                   ends: npt.NDArray[np.intp]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64],
                                                        npt.NDArray[np.float64]]:
    """Walk each optimal path of a block back from (T-1, ends[b]) to (0, 0), then measure its cells.

    Each cell names its predecessor in ``direction`` (B, T, G). The walk is a plain loop over a
    byte view of the table (under a microsecond a cell; a vectorised walk over the block paid
    ~30 numpy calls a step). Every visited cell is then measured exactly in float64, all paths at
    once, and summed per step in the order the walk visited them.

    Returns:
        (drift, total, length): (B, T) mean distance of the cells aligned to each predicted
        step, (B,) the path's total distance, and (B,) its number of cells.
    """
    B, T, _ = p.shape
    G = g.shape[0]
    path_i: list[int] = []
    path_j: list[int] = []
    path_len = np.empty(B, np.int64)
    for b in range(B):
        codes = memoryview(direction[b]).cast("B")  # codes[i * G + j]: _dtw_block made it C-ordered
        i, j = T - 1, int(ends[b])
        start = len(path_i)
        while True:
            path_i.append(i)
            path_j.append(j)
            if i == 0:  # along the table's first row only a left move stays inside it
                if j == 0:
                    break
                j -= 1
            elif j == 0:  # along its first column only an up move
                i -= 1
            else:
                code = codes[i * G + j]
                if code & _LEFT_BIT:
                    j -= 1
                elif code & _UP_BIT:
                    i -= 1
                else:
                    i -= 1
                    j -= 1
        path_len[b] = len(path_i) - start
    owner = np.repeat(np.arange(B), path_len)
    rows, cols = np.array(path_i, np.int64), np.array(path_j, np.int64)
    d = np.linalg.norm(p[owner, rows] - g[cols], axis=-1)
    cell = owner * T + rows
    drift_sum = np.bincount(cell, weights=d, minlength=B * T).reshape(B, T)
    drift_cnt = np.bincount(cell, minlength=B * T).reshape(B, T)
    total = cast(npt.NDArray[np.float64], np.bincount(owner, weights=d, minlength=B))  # float64 with weights
    return drift_sum / np.maximum(drift_cnt, 1), total, path_len.astype(np.float64)


# ----------------------------------------------------------------------------------------------
# Limits, end effector, video


def limit_violations(values: npt.ArrayLike, limits: npt.ArrayLike, margin: npt.ArrayLike = 0.0
                     ) -> npt.NDArray[np.bool_]:
    """(..., 6) True where a joint lies more than ``margin`` outside its [lower, upper] limit.

    Args:
        values: (..., 6) joint values, data units.
        limits: (6, 2) lower / upper limits, data units.
        margin: scalar or (6,) tolerance past each limit, data units (see
            :func:`inspector.units.limit_margin_in_units`).
    """
    return limit_excess(values, limits) > np.asarray(margin, np.float64)


def limit_excess(values: npt.ArrayLike, limits: npt.ArrayLike) -> Array:
    """(..., 6) how far each joint lies past its nearest limit (0 inside the range), data units."""
    v = np.asarray(values, np.float64)
    lim = np.asarray(limits, np.float64)
    return np.maximum(np.maximum(lim[:, 0] - v, v - lim[:, 1]), 0.0)


@dataclass
class LimitSummary:
    """Joint-limit violations of a run of samples, one definition everywhere it is shown.

    Attributes:
        count: joint-samples past a limit (beyond the margin), all joints together.
        steps: samples with any joint past a limit.
        by_joint: (6,) joint-samples per joint.
        max_excess: (6,) largest distance past the limit per joint among its violations (0 for
            a joint without any), data units.
    """

    count: int
    steps: int
    by_joint: npt.NDArray[np.int64]
    max_excess: Array

    @classmethod
    def of(cls, violation: npt.NDArray[np.bool_], excess: Array) -> LimitSummary:
        """From (T, 6) violation flags and (T, 6) excess."""
        by_joint = violation.sum(axis=0).astype(np.int64)
        max_excess = np.where(violation, excess, 0.0).max(axis=0) if len(excess) else np.zeros(excess.shape[-1])
        return cls(int(by_joint.sum()), int(violation.any(axis=1).sum()), by_joint, max_excess)


def psnr(pred: npt.ArrayLike, gt: npt.ArrayLike) -> Array:
    """(N,) PSNR [dB] of (N, H, W, 3) uint8 frames (peak 255); GT must already match in size.

    Exact integer arithmetic on narrow types: ``|p - g|`` in uint8, its square in uint16 (at most
    65025), row sums in uint32 (a row of under 22,000 pixels cannot overflow), frame sums in uint64.
    """
    p, g = np.asarray(pred, np.uint8), np.asarray(gt, np.uint8)
    diff = np.maximum(p, g)
    diff -= np.minimum(p, g)
    sq = diff.astype(np.uint16)
    sq *= sq
    n = len(p)
    rows = sq.reshape(n, p.shape[1], -1).sum(axis=2, dtype=np.uint32)
    sq_sum = rows.sum(axis=1, dtype=np.uint64).astype(np.float64)
    mse = np.maximum(sq_sum / (sq.size // max(n, 1)), 1e-10)
    return 10.0 * np.log10(255.0 ** 2 / mse)


def ssim(pred: npt.ArrayLike, gt: npt.ArrayLike) -> Array:
    """(N,) SSIM of (N, H, W, 3) uint8 frames on luma, 11x11 Gaussian window (sigma 1.5).

    The window is separable, so each local mean is two 11-tap passes instead of one 121-tap
    pass ("valid" windows only, as in the reference definition); float32 is ample for 8-bit frames.
    """
    def luma(x: npt.ArrayLike) -> npt.NDArray[np.float32]:
        f = np.asarray(x, np.float32)
        return 0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2]

    x, y = luma(pred), luma(gt)
    coords = np.arange(11, dtype=np.float32) - 5
    g1 = np.exp(-(coords ** 2) / (2 * 1.5 ** 2))
    g1 /= g1.sum()
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    out = np.empty(len(x))
    for n in range(len(x)):  # frame by frame: five moment images of one frame at a time
        moments = np.stack([x[n], y[n], x[n] * x[n], y[n] * y[n], x[n] * y[n]])  # (5, H, W)
        mx, my, exx, eyy, exy = _blur_valid(_blur_valid(moments, g1, axis=1), g1, axis=2)
        sxx, syy, sxy = exx - mx ** 2, eyy - my ** 2, exy - mx * my
        s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2))
        out[n] = float(s.mean(dtype=np.float64))
    return out


def _blur_valid(a: npt.NDArray[np.float32], taps: npt.NDArray[np.float32], axis: int) -> npt.NDArray[np.float32]:
    """Correlate ``a`` with ``taps`` along ``axis``, keeping only the fully covered positions."""
    k = len(taps)
    n = a.shape[axis] - k + 1
    out = np.zeros(a.shape[:axis] + (n,) + a.shape[axis + 1:], np.float32)
    for i, w in enumerate(taps):
        out += w * np.take(a, np.arange(i, i + n), axis=axis)
    return out


# ----------------------------------------------------------------------------------------------
# Two rollouts, sets of rollouts


def prompt_divergence(pred_a: npt.ArrayLike, pred_b: npt.ArrayLike, executed_per_chunk: int,
                      threshold: float = 2.0) -> tuple[Array, Array, int | None]:
    """How two rollouts from the same start (e.g. training vs novel prompt) part and meet again.

    Args:
        pred_a, pred_b: (T, 6) executed joints of the two rollouts (the shorter length is used).
        executed_per_chunk: steps per chunk.
        threshold: per-chunk mean distance (data units) under which the two count as the same.

    Returns:
        (per_step, per_chunk, collapse_chunk): ``d`` per step, its mean per chunk, and the first
        chunk from which the rollouts stay within ``threshold`` after having been apart (None if
        they never part, or never meet again).
    """
    n = min(len(cast(Sized, pred_a)), len(cast(Sized, pred_b)))
    per_step = joint_distance(np.asarray(pred_a)[:n], np.asarray(pred_b)[:n])
    per_chunk = chunk_mean(per_step, executed_per_chunk)
    close = per_chunk < threshold
    apart = np.flatnonzero(~close)
    if apart.size == 0 or apart[-1] == len(per_chunk) - 1:
        return per_step, per_chunk, None
    return per_step, per_chunk, int(apart[-1] + 1)


def chunk_mean(per_step: npt.ArrayLike, executed_per_chunk: int) -> Array:
    """(n_chunks,) mean of a (T,) per-step series over each chunk's steps (NaN-aware)."""
    x = np.asarray(per_step, np.float64)
    n = -(-len(x) // executed_per_chunk)
    padded = np.full(n * executed_per_chunk, np.nan)
    padded[: len(x)] = x
    blocks = padded.reshape(n, executed_per_chunk)
    counts = np.isfinite(blocks).sum(axis=1)
    sums = np.where(np.isfinite(blocks), blocks, 0.0).sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def aggregate(values: npt.ArrayLike) -> dict[str, float | int | None]:
    """mean / median / best (min) / worst (max) over the finite values of a set."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"n": 0, "mean": None, "median": None, "best": None, "worst": None}
    return {"n": int(v.size), "mean": float(v.mean()), "median": float(np.median(v)),
            "best": float(v.min()), "worst": float(v.max())}
