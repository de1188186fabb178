"""The per-rollout timeline: every metric over time, computed once, shared by app, report and export.

Time runs over *executed steps*: step ``s`` is the s-th action that runs (chunk ``s // E`` with
``E = executed_per_chunk``), at ``s / fps`` seconds after the rollout's start frame. For a
single-chunk rollout the steps are the whole predicted horizon.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt

from . import metrics
from .ground_truth import GroundTruth, resolve_ground_truth
from .kinematics import kinematics
from .session import Rollout
from .units import JOINT_NAMES, Units, limits_in_units

Array = npt.NDArray[np.float64]


@dataclass
class VideoMetrics:
    """Imagined vs GT frames of one view at the same times (GT resized to the imagined size).

    Attributes:
        psnr_db: (F,) per imagined frame; NaN where no GT frame exists (past the episode).
        ssim: (F,) likewise, or None when not asked for (it costs ~10x the PSNR).
    """

    view: str
    psnr_db: Array
    ssim: Array | None = None

    @property
    def mean_psnr_db(self) -> float | None:
        v = self.psnr_db[np.isfinite(self.psnr_db)]
        return float(v.mean()) if v.size else None


@dataclass
class RolloutTimeline:
    """Everything the app and the exporter draw for one rollout. Joint values in ``units``.

    Shapes: T executed steps, N chunks, H horizon, F imagined frames per view.
    """

    rollout: Rollout
    gt: GroundTruth
    units: Units
    fps: float
    executed_per_chunk: int
    horizon: int
    n_chunks: int
    t_s: Array  # (T,) seconds since the start frame
    step_chunk: npt.NDArray[np.int64]  # (T,) chunk of each step
    pred: Array  # (T, 6) executed predicted joints
    chunks: Array  # (N, H, 6) every predicted chunk (the trails)
    chunk_start_step: npt.NDArray[np.int64]  # (N,) first step of each chunk
    limits: Array  # (6, 2) joint limits in data units
    limit_violation: npt.NDArray[np.bool_]  # (T, 6)
    chunk_limit_violation: npt.NDArray[np.bool_]  # (N, H, 6)
    ee_pred: Array  # (T, 3) tool point [m]
    # With GT joints (None otherwise):
    gt_aligned: Array | None = None  # (T, 6) GT at the same time, clamped at the episode's end
    post_episode: npt.NDArray[np.bool_] | None = None  # (T,)
    time_aligned_drift: Array | None = None  # (T,)
    best_match_drift: Array | None = None  # (T,)
    best_match_index: npt.NDArray[np.int64] | None = None  # (T,) GT index (of gt.actions)
    tempo: float | None = None
    speed_mismatch: Array | None = None  # (T,)
    path_error: Array | None = None  # (T,)
    dtw_drift: Array | None = None  # (T,)
    dtw_cost: float | None = None
    joint_error: Array | None = None  # (T, 6) pred - gt, signed
    ee_gt: Array | None = None  # (T, 3) [m]
    ee_error_mm: Array | None = None  # (T,)
    chunk_errors: metrics.ChunkErrors | None = None  # over chunks fully inside the GT
    chunk_rmse: Array | None = None  # (N,) NaN for chunks without full GT
    episode_end_step: int | None = None  # first post-episode step, if the rollout outlasts it
    _video: dict[str, VideoMetrics] = field(default_factory=dict, repr=False)
    _video_lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    # -- time bookkeeping ------------------------------------------------------------------
    @property
    def n_steps(self) -> int:
        return int(self.pred.shape[0])

    @property
    def tag(self) -> str:
        return self.rollout.tag

    @property
    def kind(self) -> str:
        return self.rollout.kind

    @property
    def has_gt_joints(self) -> bool:
        return self.gt_aligned is not None

    def step_of(self, chunk: int, step_in_chunk: int) -> int:
        """Global step of ``step_in_chunk`` in ``chunk`` (clamped to the timeline)."""
        return int(np.clip(chunk * self.steps_per_chunk + step_in_chunk, 0, self.n_steps - 1))

    @property
    def steps_per_chunk(self) -> int:
        """Steps of the timeline each chunk covers (executed steps; the horizon for single chunks)."""
        return self.rollout.steps_per_chunk

    def frame_index(self, step: int) -> int:
        """Imagined frame showing ``step``."""
        chunk, within = divmod(step, self.steps_per_chunk)
        r = self.rollout
        per_chunk_frames = r.frames_per_chunk
        f = chunk * per_chunk_frames + int(within * per_chunk_frames / max(1, r.executed_per_chunk))
        return min(f, chunk * per_chunk_frames + per_chunk_frames - 1)

    def frame_step(self, n_frames: int) -> npt.NDArray[np.int64]:
        """(F,) step shown by each imagined frame."""
        r = self.rollout
        f = np.arange(n_frames)
        chunk, within = np.divmod(f, r.frames_per_chunk)
        step = chunk * self.steps_per_chunk + (within * r.executed_per_chunk) // r.frames_per_chunk
        return np.minimum(step, self.n_steps - 1)

    def per_chunk(self, series: npt.ArrayLike | None) -> Array | None:
        """(N,) mean of a (T,) series over each chunk's steps."""
        return None if series is None else metrics.chunk_mean(series, self.steps_per_chunk)

    def worst_chunk(self) -> int:
        """The chunk with the largest drift (time-aligned, else limit violations, else 0)."""
        series = self.per_chunk(self.time_aligned_drift)
        if series is None or not np.isfinite(series).any():
            series = self.per_chunk(self.limit_violation.sum(axis=1).astype(float))
        return int(np.nanargmax(series)) if series is not None and np.isfinite(series).any() else 0

    # -- video -------------------------------------------------------------------------------
    def video_views(self) -> list[str]:
        """Views with both imagined and GT frames."""
        return [v for v in self.rollout.views if v in self.gt.views]

    def video_metrics(self, view: str, with_ssim: bool = False) -> VideoMetrics:
        """PSNR (and SSIM if asked) of ``view``, computed on first request and cached."""
        with self._video_lock:
            vm = self._video.get(view)
            if vm is None or (with_ssim and vm.ssim is None):
                vm = self._compute_video_metrics(view, with_ssim)
                self._video[view] = vm
            return vm

    def gt_frames_resized(self, view: str) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.uint8]]:
        """(frames with GT, their GT frames resized to the imagined size) for ``view``."""
        imagined = self.rollout.video(view).frames
        h, w = imagined.shape[1:3]
        if view in self.rollout.gt_views:
            # carried GT: frame i pairs with imagined frame i, already decoded at the imagined size
            gt = self.rollout.video(view, gt=True).frames[: len(imagined)]
            return np.arange(len(gt)), metrics.resize_frames(gt, h, w)
        steps = self.frame_step(len(imagined))
        pairs = [(f, self.gt.frame(view, f, int(steps[f]))) for f in range(len(imagined))]
        have = np.array([f for f, g in pairs if g is not None], dtype=np.int64)
        if have.size == 0:
            return have, np.zeros((0, *imagined.shape[1:]), np.uint8)
        return have, metrics.resize_frames(np.stack([pairs[f][1] for f in have]), h, w)

    def all_video_metrics(self, views: list[str] | None = None,
                          progress: Callable[[float, str], None] | None = None) -> dict[str, VideoMetrics]:
        """PSNR of every paired view, decoding clips in worker threads while comparing the ready ones.

        PyAV decodes outside the GIL, so on two cores one clip decodes while another is compared.

        Args:
            views: views to compute (default: every view with imagined and GT frames).
            progress: optional ``progress(fraction, message)``.
        """
        from concurrent.futures import ThreadPoolExecutor

        paired = [v for v in (self.video_views() if views is None else views) if v in self.video_views()]
        out: dict[str, VideoMetrics] = {}
        with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
            decoding = {v: [pool.submit(len, self.rollout.video(v)), pool.submit(len, self.gt.clips[v])]
                        for v in paired}
            for i, view in enumerate(paired):
                if progress is not None:
                    progress(i / max(1, len(paired)), f"decoding {view} video")
                for future in decoding[view]:
                    future.result()
                if progress is not None:
                    progress((i + 0.5) / max(1, len(paired)), f"PSNR {view}")
                out[view] = self.video_metrics(view)
        return out

    def _compute_video_metrics(self, view: str, with_ssim: bool) -> VideoMetrics:
        imagined = self.rollout.video(view).frames
        psnr = np.full(len(imagined), np.nan)
        ssim = np.full(len(imagined), np.nan) if with_ssim else None
        if view in self.gt.views:
            have, gt_frames = self.gt_frames_resized(view)
            if have.size:
                psnr[have] = metrics.psnr(imagined[have], gt_frames)
                if ssim is not None:
                    ssim[have] = metrics.ssim(imagined[have], gt_frames)
        return VideoMetrics(view, psnr, ssim)


def build_timeline(rollout: Rollout, dataset_root: Path | None = None,
                   gt: GroundTruth | None = None) -> RolloutTimeline:
    """Compute every joint-space metric of ``rollout`` (video metrics stay lazy)."""
    gt = gt if gt is not None else resolve_ground_truth(rollout, dataset_root)
    units = rollout.units
    pred = rollout.executed_actions()
    n_steps = pred.shape[0]
    steps_per_chunk = rollout.steps_per_chunk
    limits = limits_in_units(units)
    fk = kinematics()
    tl = RolloutTimeline(
        rollout=rollout, gt=gt, units=units, fps=rollout.fps,
        executed_per_chunk=rollout.executed_per_chunk, horizon=rollout.horizon,
        n_chunks=rollout.n_chunks,
        t_s=np.arange(n_steps) / rollout.fps,
        step_chunk=np.arange(n_steps) // steps_per_chunk,
        pred=pred, chunks=rollout.actions,
        chunk_start_step=np.arange(rollout.n_chunks) * steps_per_chunk,
        limits=limits,
        limit_violation=metrics.limit_violations(pred, limits),
        chunk_limit_violation=metrics.limit_violations(rollout.actions, limits),
        ee_pred=fk.gripper_positions(pred, units),
    )
    steps_in_episode = gt.steps_in_episode
    if steps_in_episode is not None and steps_in_episode < n_steps:
        tl.episode_end_step = max(0, steps_in_episode)
    if gt.actions is None:
        return tl

    ta, gt_aligned, post = metrics.time_aligned(pred, gt.actions, gt.offset)
    bm, bm_index = metrics.best_match(pred, gt.actions)
    speed, path = metrics.drift_split(ta, bm)
    dtw_drift, dtw_cost = metrics.dtw(pred, gt.actions[gt.offset:])
    ee_gt = fk.gripper_positions(gt_aligned, units)
    tl.gt_aligned, tl.post_episode = gt_aligned, post
    tl.time_aligned_drift, tl.best_match_drift, tl.best_match_index = ta, bm, bm_index
    tl.tempo = metrics.tempo(bm_index, ~post) if (~post).sum() >= 2 else None
    tl.speed_mismatch, tl.path_error = speed, path
    tl.dtw_drift, tl.dtw_cost = dtw_drift, dtw_cost
    tl.joint_error = pred - gt_aligned
    tl.ee_gt = ee_gt
    tl.ee_error_mm = np.linalg.norm(tl.ee_pred - ee_gt, axis=1) * 1000.0

    # Chunk errors: each chunk's full horizon against GT over the same steps, where GT covers it.
    starts = tl.chunk_start_step + gt.offset
    idx = starts[:, None] + np.arange(rollout.horizon)[None]
    inside = idx[:, -1] < gt.actions.shape[0]
    tl.chunk_rmse = np.full(rollout.n_chunks, np.nan)
    if inside.any():
        gt_chunks = gt.actions[idx[inside]]
        tl.chunk_rmse[inside] = metrics.per_chunk_rmse(rollout.actions[inside], gt_chunks)
        tl.chunk_errors = metrics.chunk_errors(rollout.actions[inside], gt_chunks)
    return tl


__all__ = ["RolloutTimeline", "VideoMetrics", "build_timeline", "JOINT_NAMES"]
