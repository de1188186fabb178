"""The sanity measures of one rollout, as its report row carries them: chunk seams, completion,
joint coherence, where the imagined video breaks, and whether it has latents.

Each is defined in its own module under :mod:`inspector.analysis` (and in docs/metrics.md); this
one only feeds them a timeline and shapes their records (for report rows, the app and recordings).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np
import numpy.typing as npt

from ..data.session import CHAINED_KINDS
from ..robot.kinematics import kinematics
from ..units import ARM_JOINTS, to_radians
from .coherence import CoherenceJson, GtMotion, coherence_record, gt_motion
from .completion import CompletionJson, CompletionTarget, completion_record, completion_target
from .measures_switch import sanity_measures_on
from .seams import Seams, SeamsJson, jerk_p95, seam_jumps, seams_record
from .timeline import RolloutTimeline
from .video_break import VideoBreakJson, chunk_arm_travel, video_break_record
from .video_metrics import VideoMetrics


class LatentsJson(TypedDict):
    n: int
    dim: int


class SanityMeasures(TypedDict):
    seams: SeamsJson | None
    completion: CompletionJson | None
    joint_coherence: CoherenceJson | None
    video_break: dict[str, int | None]
    video_degradation: dict[str, VideoBreakJson]
    latents: LatentsJson | None


def sanity_measures(tl: RolloutTimeline, video: Mapping[str, VideoMetrics],
                    imagined_quality: Mapping[str, npt.NDArray[np.float64]] | None = None) -> SanityMeasures:
    """The five measures of ``tl`` (each null where it does not apply or cannot be measured).

    Args:
        video: its video metrics per view (their per-frame ``quality`` feeds the video break).
        imagined_quality: (F, 3) per-frame measures of views without GT video, measured apart.
    """
    if not sanity_measures_on():
        return {"seams": None, "completion": None, "joint_coherence": None, "video_break": {},
                "video_degradation": {}, "latents": None}
    chained = tl.kind in CHAINED_KINDS
    inside = ~tl.post_episode if tl.post_episode is not None else np.ones(tl.n_steps, bool)
    seams = None
    s = rollout_seams(tl)
    if s is not None:
        seams = seams_record(s, jerk_p95(tl.pred, tl.fps), _gt_side(tl, inside).jerk_p95)
    completion = None
    if chained and tl.gt.actions is not None and tl.time_aligned_drift is not None:
        target = _gt_side(tl, inside).completion
        assert target is not None
        completion = completion_record(tl.pred, tl.ee_pred, target, tl.time_aligned_drift, tl.fps)
    coherence = None
    if tl.gt_aligned is not None:
        coherence = coherence_record(tl.pred, tl.gt_aligned, inside, tl.fps, _gt_side(tl, inside).motion)
    degradation: dict[str, VideoBreakJson] = {}
    if chained:
        per_view = {v: vm.quality for v, vm in video.items() if vm.quality is not None}
        per_view.update(imagined_quality or {})
        travel = _arm_travel(tl)
        for view in sorted(per_view):
            degradation[view] = video_break_record(per_view[view], tl.rollout.frames_per_chunk,
                                                   arm_travel_deg=travel)
    latents = tl.rollout.latents
    return {"seams": seams, "completion": completion, "joint_coherence": coherence,
            "video_break": {v: d["break_chunk"] for v, d in degradation.items()},
            "video_degradation": degradation,
            "latents": None if latents is None else {"n": int(latents.shape[0]), "dim": int(latents.shape[1])}}


def _arm_travel(tl: RolloutTimeline) -> npt.NDArray[np.float64] | None:
    """(N,) how far the predicted arm moves in each chunk [deg] (a still video is frozen only
    while it moves), or None for a rollout without joints."""
    if not tl.has_joints:
        return None
    arm = np.degrees(to_radians(tl.pred, tl.units))[:, :len(ARM_JOINTS)]
    return chunk_arm_travel(arm, tl.step_chunk, tl.n_chunks)


def rollout_seams(tl: RolloutTimeline) -> Seams | None:
    """Every chunk seam of a chained rollout (None for others, and for a video-only one: its
    actions are not there, so there is no seam to measure), flagged with its tolerances."""
    if tl.kind not in CHAINED_KINDS or not tl.has_joints:
        return None
    inside = ~tl.post_episode if tl.post_episode is not None else np.ones(tl.n_steps, bool)
    return seam_jumps(tl.chunks, tl.executed_per_chunk, tl.gt_aligned, inside, tl.measures.seam_multiple,
                      tl.measures.seam_floor_deg)


@dataclass
class _GtSide:
    """The measures' GT-only parts: the same for every rollout of a batch, whose timelines share
    their GT arrays, so computed once for the batch. ``held`` keeps what they were computed from
    alive (so that identity compares them safely)."""

    held: tuple[Any, ...]  # compared by identity
    scalars: tuple[Any, ...]  # compared by value (the settings among them)
    jerk_p95: float | None
    completion: CompletionTarget | None
    motion: GtMotion | None  # the GT's velocities, for every rollout's phase offsets


_last_gt: _GtSide | None = None  # rollouts of one batch are measured one after another


def _gt_side(tl: RolloutTimeline, inside: npt.NDArray[np.bool_]) -> _GtSide:
    global _last_gt
    held, scalars = (tl.gt.actions, tl.gt_aligned, tl.post_episode), (tl.gt.offset, tl.units, tl.fps, tl.measures)
    last = _last_gt
    if last is not None and all(a is b for a, b in zip(last.held, held)) and last.scalars == scalars:
        return last
    units = tl.units
    jerk = jerk_p95(tl.gt_aligned[inside], tl.fps) if tl.gt_aligned is not None else None
    target = None
    if tl.gt.actions is not None:
        m = tl.measures
        target = completion_target(tl.gt.actions, lambda q: kinematics().gripper_positions(q, units),
                                   tl.gt.offset, tl.fps, m.completion_tol_deg, m.completion_tol_mm,
                                   m.completion_hold_s)
    motion = gt_motion(tl.gt_aligned[inside]) if tl.gt_aligned is not None else None
    _last_gt = _GtSide(held, scalars, jerk, target, motion)
    return _last_gt


def aggregate_measures(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Over the rows: flagged seams, completions, worst coupling error, video breaks."""
    chained = [r for r in rows if r.get("seams") is not None]
    completions = [r["completion"] for r in rows if r.get("completion") is not None]
    coupling = [max(c["coupling_error_deg"].values()) for r in rows
                if (c := r.get("joint_coherence")) is not None and c["coupling_error_deg"]]
    breaks = [b for r in rows for b in (r.get("video_break") or {}).values()]
    return {
        "rollouts_with_flagged_seams": sum(bool(r["seams"]["flagged"]) for r in chained),
        "flagged_seams": sum(len(r["seams"]["flagged"]) for r in chained),
        "completed": sum(c["time_s"] is not None for c in completions),
        "completion_measured": len(completions),
        "worst_coupling_error_deg": max(coupling) if coupling else None,
        "video_views_broken": sum(b is not None for b in breaks),
        "video_views_measured": len(breaks),
    }
