"""The per-rollout timeline: every metric over time, computed once, shared by app, report and export.

Time runs over *executed steps*: step ``s`` is the s-th action that runs (chunk ``s // E`` with
``E = executed_per_chunk``), at ``s / fps`` seconds after the rollout's start frame. For a
single-chunk rollout the steps are the whole predicted horizon.

Joint metrics come from :func:`inspector.analysis.sweep.sweep_metrics`, for one rollout or for a batch
that shares a GT episode (:func:`build_timelines`); video metrics stream both clips frame pair
by frame pair (:mod:`inspector.analysis.video_metrics`) and are computed on first request.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import overload

import numpy as np
import numpy.typing as npt

from ..data.ground_truth import GroundTruth, resolve_ground_truth
from ..data.session import Rollout
from ..units import DEFAULT_LIMIT_MARGIN_DEG, JOINT_NAMES, Units
from . import metrics
from .measure_settings import DEFAULT_MEASURES, MeasureSettings
from .sweep import SweepMetrics, sweep_metrics
from .video_action import JointTimes, VideoAction, agreement
from .video_metrics import VideoMetrics, compare_clips, resizes_whole_frame

Array = npt.NDArray[np.float64]


@dataclass(frozen=True)
class ArmLabels:
    """What a timeline's two arms are, in words for plots, cards and recordings.

    Attributes:
        pred: the arm in ``pred`` ("predicted" for a rollout, "commanded" for an episode).
        gt: the arm in ``gt_aligned`` ("GT" / "measured").
        drift: the time-aligned distance between them ("time-aligned drift" / "tracking error").
    """

    pred: str
    gt: str
    drift: str


ROLLOUT_LABELS = ArmLabels("predicted", "GT", "time-aligned drift")
EPISODE_LABELS = ArmLabels("commanded (action)", "measured (state)", "tracking error")


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
    limit_margin: Array  # (6,) tolerance past a limit before it counts, data units
    limit_margin_deg: float
    limit_excess: Array  # (T, 6) distance past the limit, 0 inside
    limit_violation: npt.NDArray[np.bool_]  # (T, 6) past a limit by more than the margin
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
    # the tolerances of the sanity measures (completion, seams) its rows are computed with
    measures: MeasureSettings = DEFAULT_MEASURES
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

    @property
    def has_joints(self) -> bool:
        """False for a video-only rollout: no predicted arm, no joint measure."""
        return self.rollout.has_joints

    @property
    def labels(self) -> ArmLabels:
        named = self.rollout.extra.get("arm_labels")  # an importer's own words (e.g. commanded / executed)
        if isinstance(named, dict) and all(isinstance(named.get(k), str) for k in ("pred", "gt", "drift")):
            return ArmLabels(named["pred"], named["gt"], named["drift"])
        return EPISODE_LABELS if self.kind == "episode" else ROLLOUT_LABELS

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

    def gt_index_of_frame(self, view: str) -> Callable[[int], int]:
        """``f -> index`` in ``gt.clips[view]`` of the GT frame paired with imagined frame ``f``
        (-1: none, past the episode): the same frame for carried GT, else the frame's step."""
        n_gt = self.gt.frames_in_clip(view)
        r = self.rollout

        def index_of(f: int) -> int:
            if self.gt.carried:
                i = f
            else:
                chunk, within = divmod(f, r.frames_per_chunk)
                i = min(chunk * self.steps_per_chunk + (within * r.executed_per_chunk) // r.frames_per_chunk,
                        self.n_steps - 1)
            return i if i < n_gt else -1
        return index_of

    @overload
    def per_chunk(self, series: None) -> None: ...
    @overload
    def per_chunk(self, series: npt.ArrayLike) -> Array: ...
    @overload
    def per_chunk(self, series: npt.ArrayLike | None) -> Array | None: ...

    def per_chunk(self, series: npt.ArrayLike | None) -> Array | None:
        """(N,) mean of a (T,) series over each chunk's steps."""
        return None if series is None else metrics.chunk_mean(series, self.steps_per_chunk)

    def limit_summary(self) -> metrics.LimitSummary:
        """Joint-limit violations over the executed steps (count, steps, by joint, max excess)."""
        return metrics.LimitSummary.of(self.limit_violation, self.limit_excess)

    def worst_chunk(self) -> tuple[int, str]:
        """(chunk, why): the chunk with the largest time-aligned drift when GT joints exist,
        otherwise the largest joint-limit excess; chunk 0 when neither says anything."""
        drift = self.per_chunk(self.time_aligned_drift)
        if drift is not None and np.isfinite(drift).any():
            return int(np.nanargmax(drift)), "largest time-aligned drift"
        excess = np.where(self.limit_violation, self.limit_excess, 0.0).max(axis=1)
        by_chunk = np.array([excess[self.step_chunk == c].max(initial=0.0) for c in range(self.n_chunks)])
        if by_chunk.max(initial=0.0) > 0:
            return int(np.argmax(by_chunk)), "largest joint-limit excess"
        return 0, "no GT joints and no limit violation"

    # -- video -------------------------------------------------------------------------------
    def video_views(self) -> list[str]:
        """Views with both imagined and GT frames."""
        return [v for v in self.rollout.views if v in self.gt.views]

    def video_metrics(self, view: str, with_ssim: bool = False) -> VideoMetrics:
        """PSNR (and SSIM if asked) of ``view``, streamed on first request and kept."""
        with self._video_lock:
            vm = self._video.get(view)
        if vm is None or (with_ssim and vm.ssim is None):
            clip = self.rollout.video(view)
            gt = self.gt.clips.get(view)
            vm = compare_clips(view, [clip], gt, self.gt_index_of_frame(view), with_ssim,
                               whole_frame=resizes_whole_frame(self.rollout.extra))[0]
            self.set_video_metrics(vm)
        return vm

    def video_action(self, view: str) -> VideoAction | None:
        """Video-action agreement of ``view`` (from its video metrics, computed if not yet), or
        None when the view has no GT frames."""
        if view not in self.video_views():
            return None
        vm = self.video_metrics(view)
        if vm.match is None:
            return None
        n_gt = self.gt.frames_in_clip(view)
        gt_step = np.arange(n_gt)  # a dataset clip's frame i shows step i
        if self.gt.carried:  # a carried clip's frame i pairs with imagined frame i (even past the rollout)
            r = self.rollout
            chunk, within = np.divmod(gt_step, r.frames_per_chunk)
            gt_step = chunk * self.steps_per_chunk + (within * r.executed_per_chunk) // r.frames_per_chunk
        joints = None
        if self.best_match_index is not None and self.best_match_drift is not None and self.gt.actions is not None:
            joints = JointTimes(self.pred, self.gt.actions, self.gt.offset, self.best_match_index,
                                self.best_match_drift)
        return agreement(view, vm.match, self.frame_step(vm.psnr_db.size), self.steps_per_chunk, self.fps,
                         gt_step.astype(np.float64), joints)

    def set_video_metrics(self, vm: VideoMetrics) -> None:
        """Keep a view's video metrics computed elsewhere (a cache, the app's frame loader)."""
        with self._video_lock:
            self._video[vm.view] = vm

    def known_video_metrics(self) -> dict[str, VideoMetrics]:
        """The video metrics computed so far, without computing any."""
        with self._video_lock:
            return dict(self._video)

    def all_video_metrics(self, views: list[str] | None = None,
                          progress: Callable[[float, str], None] | None = None) -> dict[str, VideoMetrics]:
        """PSNR of every paired view, one view per worker thread (PyAV decodes outside the GIL).

        Args:
            views: views to compute (default: every view with imagined and GT frames).
            progress: optional ``progress(fraction, message)``.
        """
        from concurrent.futures import ThreadPoolExecutor

        paired = [v for v in (self.video_views() if views is None else views) if v in self.video_views()]
        out: dict[str, VideoMetrics] = {}
        with ThreadPoolExecutor(max_workers=max(1, min(len(paired), os.cpu_count() or 1))) as pool:
            futures = {v: pool.submit(self.video_metrics, v) for v in paired}
            for i, view in enumerate(paired):
                if progress is not None:
                    progress(i / max(1, len(paired)), f"PSNR {view}")
                out[view] = futures[view].result()
        return out


def build_timeline(rollout: Rollout, dataset_root: Path | None = None, gt: GroundTruth | None = None,
                   limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
                   measures: MeasureSettings = DEFAULT_MEASURES) -> RolloutTimeline:
    """Compute every joint-space metric of ``rollout`` (video metrics stay lazy)."""
    gt = gt if gt is not None else resolve_ground_truth(rollout, dataset_root)
    return build_timelines([rollout], gt, limit_margin_deg, measures)[0]


def batch_key(rollout: Rollout, gt: GroundTruth) -> tuple | None:
    """Rollouts with the same key can share one :func:`build_timelines` batch (None: alone)."""
    if gt.dataset_key is None or rollout.gt_actions is not None or not rollout.has_joints:
        return None
    return (gt.dataset_key, rollout.units, rollout.kind, rollout.actions.shape, rollout.steps_per_chunk)


def build_timelines(rollouts: Sequence[Rollout], gt: GroundTruth,
                    limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
                    measures: MeasureSettings = DEFAULT_MEASURES) -> list[RolloutTimeline]:
    """Timelines of rollouts that share ``gt`` (same :func:`batch_key`), their joint metrics in
    one batch. Each rollout's numbers are the same as when it is computed alone."""
    first = rollouts[0]
    chunks = np.stack([r.actions for r in rollouts])
    # a video-only rollout has no predicted arm to hold against the GT arm: its joint measures stay None
    m = sweep_metrics(chunks, gt.actions if first.has_joints else None, first.units, first.steps_per_chunk, gt.offset, limit_margin_deg,
                      alignments=first.kind != "episode")
    timelines = [_timeline(r, gt, m, b, limit_margin_deg) for b, r in enumerate(rollouts)]
    for tl in timelines:
        tl.measures = measures
    return timelines


def _timeline(rollout: Rollout, gt: GroundTruth, m: SweepMetrics, b: int, margin_deg: float) -> RolloutTimeline:
    """Rollout ``b`` of a sweep as a timeline."""
    pred = m.pred[b]
    n_steps = pred.shape[0]
    steps_per_chunk = rollout.steps_per_chunk
    tl = RolloutTimeline(
        rollout=rollout, gt=gt, units=rollout.units, fps=rollout.fps,
        executed_per_chunk=rollout.executed_per_chunk, horizon=rollout.horizon,
        n_chunks=rollout.n_chunks,
        t_s=np.arange(n_steps) / rollout.fps,
        step_chunk=np.arange(n_steps) // steps_per_chunk,
        pred=pred, chunks=rollout.actions,
        chunk_start_step=np.arange(rollout.n_chunks) * steps_per_chunk,
        limits=m.limits, limit_margin=m.limit_margin, limit_margin_deg=margin_deg,
        limit_excess=m.limit_excess[b], limit_violation=m.limit_violation[b],
        chunk_limit_violation=m.chunk_limit_violation[b],
        ee_pred=m.ee_pred[b],
    )
    steps_in_episode = gt.steps_in_episode
    if steps_in_episode is not None and steps_in_episode < n_steps:
        tl.episode_end_step = max(0, steps_in_episode)
    if m.gt_aligned is None:
        return tl
    # sweep_metrics sets these together with gt_aligned, and the alignments together
    assert m.time_aligned_drift is not None and m.ee_error_mm is not None and m.chunk_rmse is not None
    tl.gt_aligned, tl.post_episode = m.gt_aligned, m.post_episode
    tl.time_aligned_drift = m.time_aligned_drift[b]
    if m.best_match_drift is not None:
        assert (m.best_match_index is not None and m.tempo is not None and m.speed_mismatch is not None
                and m.path_error is not None and m.dtw_drift is not None and m.dtw_cost is not None)
        tl.best_match_drift, tl.best_match_index = m.best_match_drift[b], m.best_match_index[b]
        tempo = float(m.tempo[b])
        tl.tempo = tempo if np.isfinite(tempo) else None
        tl.speed_mismatch, tl.path_error = m.speed_mismatch[b], m.path_error[b]
        tl.dtw_drift, tl.dtw_cost = m.dtw_drift[b], float(m.dtw_cost[b])
    tl.joint_error = pred - m.gt_aligned
    tl.ee_gt, tl.ee_error_mm = m.ee_gt, m.ee_error_mm[b]
    tl.chunk_rmse = m.chunk_rmse[b]
    if m.chunks_inside is not None and m.chunks_inside.any():
        assert m.rmse is not None and m.per_step_mse is not None and m.per_joint_rmse is not None  # set with chunks_inside
        tl.chunk_errors = metrics.ChunkErrors(float(m.rmse[b]), m.per_step_mse[b], m.per_joint_rmse[b])
    return tl


__all__ = ["ArmLabels", "RolloutTimeline", "VideoMetrics", "build_timeline", "build_timelines", "batch_key",
           "JOINT_NAMES"]
