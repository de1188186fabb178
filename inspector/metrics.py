"""Drift metrics, exactly as DESIGN §5 defines them; vectorised, no loop over timesteps.

All joint-space figures are in the data's own units (arm degrees or -100..100, gripper 0..100):
``d(a, b) = ||a - b||_2`` over the 6 joints. Functions take a leading batch axis where it helps
(1,000 rollouts at once for a sweep) and plain (T, 6) arrays otherwise.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from typing import Iterator

import numpy as np
import numpy.typing as npt
import torch

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


def time_aligned(pred: npt.ArrayLike, gt: npt.ArrayLike, offset: int = 0) -> tuple[Array, Array, Array]:
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


def _squared_distances(p: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    """(B, T, G) squared joint distances of (B, T, 6) against (G, 6), as one matmul.

    ``|a - b|^2 = |a|^2 + |b|^2 - 2 a.b`` written as ``[a, |a|^2, 1] . [-2b, 1, |b|^2]``: BLAS
    writes the table in one pass with no broadcast temporaries. float64 keeps the cancellation
    error near 1e-12 of the squared magnitudes.
    """
    ones_p = torch.ones(p.shape[:-1] + (1,), dtype=p.dtype)
    ones_g = torch.ones(g.shape[:-1] + (1,), dtype=g.dtype)
    p_aug = torch.cat([p, (p * p).sum(-1, keepdim=True), ones_p], dim=-1)
    g_aug = torch.cat([-2.0 * g, ones_g, (g * g).sum(-1, keepdim=True)], dim=-1)
    return torch.matmul(p_aug, g_aug.T).clamp_(min=0.0)


def best_match(pred: npt.ArrayLike, gt: npt.ArrayLike) -> tuple[Array, npt.NDArray[np.int64]]:
    """Distance to the nearest GT pose anywhere in the episode (speed-invariant).

    A KD-tree over the episode's poses answers each predicted sample exactly in O(log G), so a
    sweep of 1,000 rollouts never builds the (B, T, G) distance table.

    Args:
        pred: (..., T, 6).
        gt: (G, 6).

    Returns:
        (drift, index): (..., T) ``min_j d(pred(t), gt_j)`` and its argmin j (the GT frame the
        arm "is at").
    """
    from scipy.spatial import cKDTree

    p = np.asarray(pred, np.float64)
    g = np.asarray(gt, np.float64)
    if len(g) == 0:
        raise ValueError("best_match: the GT episode is empty")
    drift, nearest = cKDTree(g).query(p.reshape(-1, g.shape[1]), k=1, workers=-1)
    nearest = np.minimum(nearest, len(g) - 1)  # the tree answers len(g) for an infinite distance
    # A GT hold (the arm at rest) repeats one pose over many frames, and every frame of it ties;
    # an arbitrary one of them would bias the tempo fit, so each match moves to the middle of its run.
    index = _middle_of_identical_runs(g)[nearest]
    return drift.reshape(p.shape[:-1]), index.reshape(p.shape[:-1])


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
    Rollouts are processed in blocks, one thread per core: the row operations are too small for
    torch's own threads to pay off, but whole blocks run side by side.

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
    squeeze = p.ndim == 2
    if squeeze:
        p = p[None]
    block = max(1, min(256, -(-len(p) // (os.cpu_count() or 1))))
    blocks = [p[i:i + block] for i in range(0, len(p), block)]
    with _torch_threads(1), ThreadPoolExecutor(max_workers=min(len(blocks), os.cpu_count() or 1)) as pool:
        results = list(pool.map(lambda b: _dtw_block(b, g), blocks))
    drift = np.concatenate([r[0] for r in results])
    cost = np.concatenate([r[1] for r in results])
    return (drift[0], float(cost[0])) if squeeze else (drift, cost)


@contextlib.contextmanager
def _torch_threads(n: int) -> Iterator[None]:
    """Run a block of torch work with ``n`` intra-op threads, then restore the previous count."""
    previous = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _dtw_block(p: npt.NDArray[np.float64], g: npt.NDArray[np.float64]) -> tuple[Array, Array]:
    """DTW of a (B, T, 6) block against (G, 6), one vector operation per predicted step.

    Within a row, ``D[i, j] = min(a_j, c_ij + D[i, j-1])`` with ``a_j = c_ij + min(D[i-1, j-1],
    D[i-1, j])`` is a min-plus scan: with ``S`` the running sum of the row's costs,
    ``D[i, :] = S + cummin(a - S)``. So each row is a cumsum and a cummin, not a loop over j.
    Tables are laid out (T, G, B) so every scan runs along the outer axis over contiguous rows.
    Costs are float32 and made row by row: they only choose the path; the backtrack measures the
    chosen cells exactly.
    """
    B, T, _ = p.shape
    G = g.shape[0]
    centre = g.mean(axis=0)
    # absurd inputs (1e30 deg) would overflow float32 to inf: clip, the path is measured in float64 anyway
    limit = np.finfo(np.float32).max / 1e3
    pc = torch.from_numpy(np.clip(p - centre, -limit, limit).astype(np.float32)).permute(1, 0, 2).contiguous()  # (T, B, 6)
    gc = torch.from_numpy(np.clip(g - centre, -limit, limit).astype(np.float32))  # (G, 6)
    g_sq = (gc * gc).sum(-1)[:, None]  # (G, 1)
    # acc[i + 1, j + 1] = D[i, j]; row 0 and column 0 are the boundary (inf, 0 at the origin)
    acc = torch.empty((T + 1, G + 1, B), dtype=torch.float32)
    acc[0] = float("inf")
    acc[:, 0] = float("inf")
    acc[0, 0] = 0.0
    cost = torch.empty((G, B), dtype=torch.float32)
    a = torch.empty((G, B), dtype=torch.float32)
    running = torch.empty((G, B), dtype=torch.float32)
    argmin = torch.empty((G, B), dtype=torch.long)
    for i in range(T):
        p_i = pc[i]  # (B, 6)
        torch.addmm(g_sq + (p_i * p_i).sum(-1)[None], gc, p_i.T, beta=1.0, alpha=-2.0, out=cost)
        cost.clamp_(min=0.0).sqrt_()
        prev = acc[i]
        torch.minimum(prev[:-1], prev[1:], out=a)
        a += cost
        torch.cumsum(cost, dim=0, out=running)
        a -= running
        row = acc[i + 1, 1:]
        torch.cummin(a, dim=0, out=(row, argmin))
        row += running
    drift, total, length = _dtw_backtrack(p, g, acc.permute(2, 0, 1).numpy())
    return drift, total / length


def _dtw_backtrack(p: npt.NDArray[np.float64], g: npt.NDArray[np.float64], acc: npt.NDArray[np.float32]
                   ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Walk every optimal path of a block back from (T-1, G-1) to (0, 0) together.

    Each step goes to the cheapest of the three predecessors in the accumulated table (the
    diagonal first on ties, as textbook DTW does) and measures its cell exactly in float64.

    Returns:
        (drift, total, length): (B, T) mean distance of the cells aligned to each predicted
        step, (B,) the path's total distance, and (B,) its number of cells.
    """
    B, T, _ = p.shape
    G = g.shape[0]
    total = np.zeros(B)
    drift_sum = np.zeros((B, T))
    drift_cnt = np.zeros((B, T))
    length = np.zeros(B)
    bi = np.full(B, T - 1)
    bj = np.full(B, G - 1)
    rows = np.arange(B)
    for _ in range(T + G - 1):  # every path has at most T + G - 1 cells
        active = bi >= 0
        if not active.any():
            break
        r, i, j = rows[active], bi[active], bj[active]
        d = np.linalg.norm(p[r, i] - g[j], axis=-1)
        drift_sum[r, i] += d
        total[r] += d
        drift_cnt[r, i] += 1
        length[r] += 1
        done = (i == 0) & (j == 0)
        # predecessors of cell (i, j) sit at acc[i, j] (diagonal), acc[i, j+1] (above), acc[i+1, j] (left)
        options = np.stack([acc[r, i, j], acc[r, i, j + 1], acc[r, i + 1, j]])
        move = np.argmin(options, axis=0)
        bi[r] = np.where(done, -1, i - (move != 2))
        bj[r] = np.where(done, -1, j - (move != 1))
    return drift_sum / np.maximum(drift_cnt, 1), total, length


# ----------------------------------------------------------------------------------------------
# Limits, end effector, video


def limit_violations(values: npt.ArrayLike, limits: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """(..., 6) True where a joint lies outside its [lower, upper] limit (both in data units)."""
    v = np.asarray(values, np.float64)
    lim = np.asarray(limits, np.float64)
    return (v < lim[:, 0]) | (v > lim[:, 1])


def psnr(pred: npt.ArrayLike, gt: npt.ArrayLike) -> Array:
    """(N,) PSNR [dB] of (N, H, W, 3) uint8 frames (peak 255); GT must already match in size."""
    p, g = np.asarray(pred), np.asarray(gt)
    # integer arithmetic: exact, and far cheaper than float64 on 8-bit frames
    diff = np.subtract(p, g, dtype=np.int16).reshape(len(p), -1)
    sq_sum = np.einsum("ij,ij->i", diff, diff, dtype=np.int64)
    mse = np.maximum(sq_sum / diff.shape[1], 1e-10)
    return 10.0 * np.log10(255.0 ** 2 / mse)


def ssim(pred: npt.ArrayLike, gt: npt.ArrayLike) -> Array:
    """(N,) SSIM of (N, H, W, 3) uint8 frames on luma, 11x11 Gaussian window (sigma 1.5).

    The window is separable, so each local mean is two 11-tap passes instead of one 121-tap
    pass; float32 is ample for 8-bit frames.
    """
    def luma(x: npt.ArrayLike) -> torch.Tensor:
        t = torch.as_tensor(np.asarray(x)).to(torch.float32)
        return 0.299 * t[..., 0] + 0.587 * t[..., 1] + 0.114 * t[..., 2]

    x, y = luma(pred), luma(gt)
    coords = torch.arange(11, dtype=torch.float32) - 5
    g1 = torch.exp(-(coords ** 2) / (2 * 1.5 ** 2))
    g1 = g1 / g1.sum()
    # the five local moments of each frame go through the blur together, as channels
    stack = torch.stack([x, y, x * x, y * y, x * y], dim=1)  # (N, 5, H, W)
    vertical = g1.view(1, 1, 11, 1).repeat(5, 1, 1, 1)
    horizontal = g1.view(1, 1, 1, 11).repeat(5, 1, 1, 1)
    out = []
    for block in torch.split(stack, 32):
        m = torch.nn.functional.conv2d(torch.nn.functional.conv2d(block, vertical, groups=5), horizontal, groups=5)
        mx, my, exx, eyy, exy = m.unbind(dim=1)
        c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
        sxx, syy, sxy = exx - mx ** 2, eyy - my ** 2, exy - mx * my
        s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2))
        out.append(s.mean(dim=(1, 2)).to(torch.float64))
    return torch.cat(out).numpy()


def resize_frames(frames: npt.ArrayLike, height: int, width: int) -> npt.NDArray[np.uint8]:
    """(N, h, w, 3) uint8 -> (N, height, width, 3) uint8, antialiased bilinear."""
    f = np.asarray(frames)
    if f.shape[1:3] == (height, width):
        return f
    t = torch.as_tensor(f).permute(0, 3, 1, 2).to(torch.float32)
    t = torch.nn.functional.interpolate(t, size=(height, width), mode="bilinear", antialias=True,
                                        align_corners=False)
    return t.round().clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()


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
    n = min(len(pred_a), len(pred_b))
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
