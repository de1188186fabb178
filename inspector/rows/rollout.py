"""What ``inspector report`` says about one rollout (a JSON row) and about a set of them.

Rows are small and self-contained, so a report over thousands of rollouts keeps only rows, and
the metrics cache stores them as they are. A rollout's row is written as :class:`RolloutRow`
says (mypy checks :func:`rollout_summary` against it), and the cache reads one back only if it
still is one (:func:`inspector.schema.mismatch`).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Mapping
from typing import Annotated, Any, TypedDict, cast

import numpy as np
import numpy.typing as npt

from ..analysis import metrics
from ..analysis.gripper_track import GripperPixels
from ..analysis.masked_psnr import MaskedPsnr
from ..analysis.sanity import CoherenceJson, CompletionJson, LatentsJson, SeamsJson, VideoBreakJson, aggregate_measures, sanity_measures
from ..analysis.timeline import RolloutTimeline
from ..analysis.video_action import ViewAgreementJson
from ..analysis.video_metrics import VideoMetrics
from ..data.session import RolloutKind
from ..schema import Keys, Length
from ..units import JOINT_NAMES
from .outcomes import success_by_task, success_overall

PerJoint = Annotated[list[float], Length(len(JOINT_NAMES))]  # JOINT_NAMES order


class DriftSummary(TypedDict):
    """A drift series [deg] over in-episode samples, and its per-chunk means (all samples)."""

    mean: float
    final: float
    per_chunk: list[float]


class EndEffectorError(TypedDict):
    """Tool-point distance to GT [mm] over in-episode samples."""

    mean: float
    final: float


class LimitRecord(TypedDict):
    """See :func:`limit_record`."""

    count: int
    steps: int
    by_joint: Annotated[dict[str, int], Keys(JOINT_NAMES)]
    max_excess: Annotated[dict[str, float], Keys(JOINT_NAMES)]
    margin_deg: float


class WorstChunk(TypedDict):
    chunk: int
    by: str


class ChunkJoints(TypedDict):
    """A single chunk's (H, 6) predicted and GT joints (a GT step null past the episode)."""

    pred: list[PerJoint]
    gt: list[PerJoint | None] | None


class RolloutRow(TypedDict):
    """One rollout in ``inspector report`` (see :func:`rollout_summary`)."""

    tag: str
    session: str | None
    kind: RolloutKind
    prompt: str
    episode_index: int | None
    start_frame: int
    units: str
    n_chunks: int
    steps_per_chunk: int
    episode_length: int | None
    rmse_deg: float | None
    per_joint_rmse: PerJoint | None
    per_step_mse: list[float] | None
    time_aligned_drift: DriftSummary | None
    best_match_drift: DriftSummary | None
    dtw_drift: DriftSummary | None
    tempo: float | None
    ee_error_mm: EndEffectorError | None
    video_only: bool  # no predicted joints: every joint field is null, never 0
    limit_violations: LimitRecord | None
    worst_chunk: WorstChunk | None
    video_psnr_db: dict[str, float]  # per view compared; a view not compared is absent ...
    video_psnr_note: dict[str, str]  # ... and here, saying why (frames of another geometry)
    video_per_chunk: dict[str, VideoPerChunk]  # per view; imagined frame f in chunk f // frames_per_chunk
    video_action: dict[str, ViewAgreementJson] | None  # per view; null with video_action_note saying why
    video_action_note: str | None
    # per view with GT video: PSNR inside / outside the projected GT arm, and the imagined gripper
    # tracked against the projected predicted one (analysis/camera_measures.py); null: no camera
    video_psnr_masked: dict[str, MaskedPsnr | None]
    gripper_px: dict[str, GripperPixels | None]
    post_episode_chunks: int | None
    gt_source: str
    gt_warning: str | None
    chunk_joints: ChunkJoints | None
    outcome: dict[str, Any] | None  # a simulated evaluation's verdict (lerobot-eval): success, rewards, task
    distribution: str | None  # "training" or "zero-shot" as the rollout states it (extra.distribution); null: not stated
    # the sanity measures (analysis/sanity.py's SanityMeasures; listed here, not inherited: the
    # cache reads a row back in this class's key order, which is the order the row is written in)
    seams: SeamsJson | None
    completion: CompletionJson | None
    joint_coherence: CoherenceJson | None
    video_break: dict[str, int | None]
    video_degradation: dict[str, VideoBreakJson]
    latents: LatentsJson | None


class VideoPerChunk(TypedDict):
    psnr_db: list[float | None]  # per chunk: mean over its imagined frames with a GT frame; null: none
    ssim: list[float | None] | None  # likewise; null where SSIM was not computed


def video_per_chunk(tl: RolloutTimeline, vm: VideoMetrics) -> VideoPerChunk:
    """A view's PSNR (and SSIM) per chunk: the mean over each chunk's imagined frames (frame f
    belongs to chunk f // frames_per_chunk; a leading frame past the last chunk to the last)."""
    chunk = np.minimum(np.arange(vm.psnr_db.size) // max(1, tl.rollout.frames_per_chunk), tl.n_chunks - 1)

    def means(values: npt.NDArray[np.float64]) -> list[float | None]:
        out: list[float | None] = []
        for c in range(tl.n_chunks):
            v = values[(chunk == c) & np.isfinite(values)]
            out.append(round(float(v.mean()), 6) if v.size else None)
        return out
    return {"psnr_db": means(vm.psnr_db), "ssim": means(vm.ssim) if vm.ssim is not None else None}


def limit_steps(row: Mapping[str, Any]) -> int | None:
    """Steps with a joint past its limit, or None for a video-only row (no joints to be past one)."""
    lim = row.get("limit_violations")
    return None if lim is None else int(lim["steps"])


def limit_margin(rows: Iterable[Mapping[str, Any]]) -> float | None:
    """The joint-limit margin [deg] of the first row with joints (None when none has)."""
    return next((r["limit_violations"]["margin_deg"] for r in rows if r.get("limit_violations")), None)


def _in_episode(tl: RolloutTimeline, series: np.ndarray) -> np.ndarray:
    """The samples of a (T,) series before the real episode's end (all of them if none are)."""
    inside = series if tl.post_episode is None else series[~tl.post_episode]
    return inside if inside.size else series


def _drift_summary(tl: RolloutTimeline, series: np.ndarray | None) -> DriftSummary | None:
    """mean / final over in-episode samples, plus the per-chunk means (all samples)."""
    if series is None:
        return None
    inside = _in_episode(tl, series)
    per_chunk = tl.per_chunk(series)
    return {"mean": float(inside.mean()), "final": float(inside[-1]),
            "per_chunk": [round(float(v), 6) for v in per_chunk]}


def limit_record(summary: metrics.LimitSummary, margin_deg: float) -> LimitRecord:
    """The ``limit_violations`` field: joint-steps (``count``), steps with any joint past a
    limit (``steps``), per joint, the largest excess per joint (data units), and the margin."""
    return {"count": summary.count, "steps": summary.steps,
            "by_joint": {j: int(c) for j, c in zip(JOINT_NAMES, summary.by_joint)},
            "max_excess": {j: round(float(e), 6) for j, e in zip(JOINT_NAMES, summary.max_excess)},
            "margin_deg": float(margin_deg)}


def rollout_summary(tl: RolloutTimeline, video: Mapping[str, VideoMetrics],
                    imagined_quality: Mapping[str, np.ndarray] | None = None,
                    camera_rows: tuple[dict[str, MaskedPsnr | None], dict[str, GripperPixels | None]] | None = None
                    ) -> dict[str, Any]:
    """The JSON record of one rollout (fields needing GT joints are null without them).

    Args:
        tl: the rollout's timeline.
        video: its video metrics per view (views without GT frames may be left out).
        imagined_quality: per-frame no-reference measures of views without GT video.
        camera_rows: ``video_psnr_masked`` and ``gripper_px``
            (:func:`inspector.analysis.camera_measures.view_records`); None: every view null.
    """
    r = tl.rollout
    ce = tl.chunk_errors
    post_chunks = None
    if tl.episode_end_step is not None:
        post_chunks = int((tl.chunk_start_step >= tl.episode_end_step).sum())
    elif tl.has_gt_joints or tl.gt.episode_length is not None:
        post_chunks = 0
    ee: EndEffectorError | None = None
    if tl.ee_error_mm is not None:
        inside = _in_episode(tl, tl.ee_error_mm)
        ee = {"mean": float(inside.mean()), "final": float(inside[-1])}
    psnr = {view: vm.mean_psnr_db for view, vm in sorted(video.items()) if vm.mean_psnr_db is not None}
    agreement, agreement_note = video_action_record(tl, video)
    worst, worst_by = tl.worst_chunk()
    joints = tl.has_joints
    sanity = sanity_measures(tl, video, imagined_quality)
    episode_length = None
    if tl.gt.episode_length is not None:  # counted from the rollout's step 0: back to the episode's start
        episode_length = int(tl.gt.episode_length - tl.gt.offset + r.start_frame)
    row: RolloutRow = {
        "tag": r.tag,
        "session": r.session.name if r.session is not None else None,
        "kind": r.kind,
        "prompt": r.prompt,
        "episode_index": r.episode_index,
        "start_frame": r.start_frame,
        "units": tl.units.label(),
        "n_chunks": tl.n_chunks,
        "steps_per_chunk": tl.steps_per_chunk,
        "episode_length": episode_length,
        "rmse_deg": ce.rmse if ce is not None else None,
        "per_joint_rmse": ce.per_joint_rmse.tolist() if ce is not None else None,
        "per_step_mse": ce.per_step_mse.tolist() if ce is not None else None,
        "time_aligned_drift": _drift_summary(tl, tl.time_aligned_drift),
        "best_match_drift": _drift_summary(tl, tl.best_match_drift),
        "dtw_drift": _drift_summary(tl, tl.dtw_drift),
        "tempo": tl.tempo,
        "ee_error_mm": ee,
        "video_only": not joints,
        "limit_violations": limit_record(tl.limit_summary(), tl.limit_margin_deg) if joints else None,
        "worst_chunk": {"chunk": worst, "by": worst_by} if joints else None,
        "video_psnr_db": psnr,
        "video_psnr_note": {view: vm.note for view, vm in sorted(video.items()) if vm.note is not None},
        "video_per_chunk": {view: video_per_chunk(tl, vm) for view, vm in sorted(video.items())
                            if vm.mean_psnr_db is not None},
        "video_action": agreement,
        "video_action_note": agreement_note,
        "video_psnr_masked": camera_rows[0] if camera_rows else {v: None for v in sorted(tl.video_views())},
        "gripper_px": camera_rows[1] if camera_rows else {v: None for v in sorted(tl.video_views())},
        "post_episode_chunks": post_chunks,
        "gt_source": tl.gt.source,
        "gt_warning": tl.gt.warning,
        "chunk_joints": _chunk_joints(tl) if joints else None,
        # a simulated evaluation's verdict (success, rewards, task), as its importer kept it
        "outcome": r.extra.get("outcome"),
        # which data the sample comes from, as its importer states it (sanity test 1 judges the training one)
        "distribution": d if isinstance(d := r.extra.get("distribution"), str) else None,
        "seams": sanity["seams"],
        "completion": sanity["completion"],
        "joint_coherence": sanity["joint_coherence"],
        "video_break": sanity["video_break"],
        "video_degradation": sanity["video_degradation"],
        "latents": sanity["latents"],
    }
    return cast(dict[str, Any], row)  # a plain dict from here on, as every other report record


def video_action_record(tl: RolloutTimeline, video: Mapping[str, VideoMetrics]
                        ) -> tuple[dict[str, ViewAgreementJson] | None, str | None]:
    """The ``video_action`` field (per view: lag, matched fraction, split chunk, video tempo) and,
    where it is null, why."""
    views = [v for v in sorted(video) if video[v].match is not None]
    if not views:
        why = "no GT video" if not tl.video_views() else "video not compared"
        return None, f"not measured: {why}"
    out: dict[str, ViewAgreementJson] = {}
    for view in views:
        va = tl.video_action(view)
        if va is not None:
            out[view] = va.summary()
    return out, None


def _chunk_joints(tl: RolloutTimeline) -> ChunkJoints | None:
    """A single chunk's predicted and GT joints, (H, 6) each (GT null without GT joints, a step
    null past the episode's end), for the overlay figures; null for autoregressive rollouts, whose
    rows stay small."""
    if tl.n_chunks != 1:
        return None
    gt = None
    if tl.gt_aligned is not None:
        inside = ~tl.post_episode if tl.post_episode is not None else np.ones(tl.n_steps, bool)
        gt = [_rounded(q) if ok else None for q, ok in zip(tl.gt_aligned, inside)]
    return {"pred": [_rounded(q) for q in tl.pred], "gt": gt}


def _rounded(q: np.ndarray) -> list[float]:
    return [round(float(v), 4) for v in q]


def aggregate(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """mean / median / best / worst RMSE over the rows, the mean PSNR of each view, and success
    rates per task and overall (see :mod:`inspector.report.outcomes`)."""
    rmse = metrics.aggregate([r["rmse_deg"] for r in rows if r["rmse_deg"] is not None])
    by_view: dict[str, list[float]] = defaultdict(list)
    for r in rows:
        for view, value in r["video_psnr_db"].items():
            by_view[view].append(value)
    return {
        "n": len(rows),
        "mean_rmse_deg": rmse["mean"],
        "median_rmse_deg": rmse["median"],
        "best_rmse_deg": rmse["best"],
        "worst_rmse_deg": rmse["worst"],
        # per view: one average of front and wrist would hide which camera the model gets right
        "mean_video_psnr_db": {view: float(np.mean(v)) for view, v in sorted(by_view.items())},
        # success rates with their Wilson intervals, over the rows' effective outcomes
        **({"success_by_task": by_task, "success_overall": success_overall(by_task)}
           if (by_task := success_by_task(rows)) else {}),
        "sanity_measures": aggregate_measures(rows),
    }


def prompt_pairs(entries: Iterable[tuple[Any, tuple, str, str]]) -> list[tuple[Any, Any]]:
    """Pairs of autoregressive rollouts to compare for prompt divergence.

    Rollouts with the same start (session, episode, start frame) are grouped. Within a group, for
    each two prompts, every rollout of the rarer prompt is paired with the rollout of the other
    prompt whose tag shares the longest prefix with its own (``ep000_train`` with ``ep000_novel``,
    ``prompt_train`` with ``prompt_novel``): found by bisection in the sorted tags, so a group of
    thousands costs n log n, never all against all.

    Args:
        entries: (handle, start, tag, prompt) of each autoregressive rollout; the handles come
            back in the pairs, ordered (first prompt, second prompt) in sorted prompt order.
    """
    groups: dict[tuple, dict[str, list[tuple[str, Any]]]] = defaultdict(lambda: defaultdict(list))
    for handle, start, tag, prompt in entries:
        groups[start][prompt].append((tag, handle))
    pairs = []
    for by_prompt in groups.values():
        prompts = sorted(by_prompt)
        for i, pa in enumerate(prompts):
            for pb in prompts[i + 1:]:
                a, b = sorted(by_prompt[pa], key=_tag), sorted(by_prompt[pb], key=_tag)
                few, many, flipped = (a, b, False) if len(a) <= len(b) else (b, a, True)
                tags = [t for t, _ in many]
                for tag, handle in few:
                    match = many[nearest_tag(tags, tag)][1]
                    pairs.append((match, handle) if flipped else (handle, match))
    return pairs


def _tag(entry: tuple[str, Any]) -> str:
    return entry[0]


def nearest_tag(sorted_tags: list[str], tag: str) -> int:
    """Index of the tag sharing the longest prefix with ``tag`` (a neighbour in sorted order)."""
    import bisect
    import os.path

    i = bisect.bisect_left(sorted_tags, tag)
    candidates = [j for j in (i - 1, i) if 0 <= j < len(sorted_tags)]
    return max(candidates, key=lambda j: (len(os.path.commonprefix([sorted_tags[j], tag])), -j))


def prompt_divergence_record(a, b) -> dict[str, Any]:
    """The ``prompt_divergence`` entry of two rollouts (:class:`inspector.data.session.Rollout`)."""
    _, per_chunk, collapse = metrics.prompt_divergence(a.executed_actions(), b.executed_actions(),
                                                        a.steps_per_chunk)
    return {"a": a.tag, "b": b.tag, "prompt_a": a.prompt, "prompt_b": b.prompt,
            "mean": float(per_chunk.mean()), "max": float(per_chunk.max()),
            "per_chunk": [round(float(v), 6) for v in per_chunk],
            "collapse_chunk": collapse}


def episode_summary(tl: RolloutTimeline) -> dict[str, Any]:
    """The JSON record of an episode for dataset triage (``report DATASET``).

    Tracking error is ``action - state`` per joint (the commanded arm ahead of or behind the
    measured one); joint ranges and limit violations are those of the measured arm and of the
    commanded arm.
    """
    r = tl.rollout
    # an episode's timeline always has GT joints (the measured arm)
    assert (tl.joint_error is not None and tl.gt_aligned is not None and tl.time_aligned_drift is not None
            and tl.ee_error_mm is not None)
    err = np.abs(tl.joint_error)
    state = tl.gt_aligned
    measured_excess = metrics.limit_excess(state, tl.limits)
    measured = metrics.LimitSummary.of(measured_excess > tl.limit_margin, measured_excess)
    return {
        "dataset": r.extra.get("dataset_name"),
        "episode_index": r.episode_index,
        "task": r.prompt,
        "length": tl.n_steps,
        "duration_s": tl.n_steps / tl.fps,
        "units": tl.units.label(),
        "tracking_error": {
            "l2_mean": float(tl.time_aligned_drift.mean()), "l2_max": float(tl.time_aligned_drift.max()),
            "mean": {j: float(v) for j, v in zip(JOINT_NAMES, err.mean(axis=0))},
            "max": {j: float(v) for j, v in zip(JOINT_NAMES, err.max(axis=0))},
            "rmse": tl.chunk_errors.per_joint_rmse.tolist() if tl.chunk_errors is not None else None,
        },
        "ee_tracking_error_mm": {"mean": float(tl.ee_error_mm.mean()), "max": float(tl.ee_error_mm.max())},
        "limit_violations": {"measured": limit_record(measured, tl.limit_margin_deg),
                             "commanded": limit_record(tl.limit_summary(), tl.limit_margin_deg)},
        "joint_range": {j: [float(lo), float(hi)] for j, lo, hi in zip(JOINT_NAMES, state.min(axis=0), state.max(axis=0))},
    }
