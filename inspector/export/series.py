"""Every metric of the timeline as a named, coloured series over time; markers and events.

Each series is one entity: its style (``SeriesLines`` / ``SeriesPoints``) is logged once, static,
and its values for all steps in one ``send_columns`` call. Non-finite samples (PSNR past the GT
video, chunks without full GT) are left out rather than drawn as zeros.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt
import rerun as rr

from ..analysis.timeline import RolloutTimeline
from ..analysis.video_action import FROZEN, NO_MATCH, VideoAction, frozen_note
from ..units import JOINT_NAMES
from . import layout as L

# timeline steps (or imagined frames) -> their time / frame / chunk columns
IndexesFor = Callable[[npt.NDArray[np.int64]], list[rr.TimeColumn]]


def log_series(rec: rr.RecordingStream, entity: str, steps: npt.ArrayLike, values: npt.ArrayLike,
               indexes_for: IndexesFor, name: str, rgba: Sequence[int], width: float = 1.5,
               points: bool = False, marker: rr.components.MarkerShapeLike = "circle", marker_size: float = 4.0) -> int:
    """One scalar series at timeline ``steps``. Returns the number of samples sent.

    Args:
        indexes_for: ``steps -> [TimeColumn, ...]`` for the rows kept.
        points: draw markers (``SeriesPoints``) instead of a line.
    """
    steps = np.asarray(steps, dtype=np.int64)
    values = np.asarray(values, dtype=np.float64)
    keep = np.isfinite(values)
    style = (rr.SeriesPoints(names=name, colors=[rgba], markers=marker, marker_sizes=marker_size)
             if points else rr.SeriesLines(names=name, colors=[rgba], widths=width))
    rec.log(entity, style, static=True)
    if keep.any():
        rec.send_columns(entity, indexes_for(steps[keep]), rr.Scalars.columns(scalars=values[keep]))
    return int(keep.sum())


def log_metric_series(rec: rr.RecordingStream, tl: RolloutTimeline, indexes_for: IndexesFor) -> None:
    """Drift, per-joint error, tool-point error, joint values and limits, chunk RMSE."""
    steps = np.arange(tl.n_steps)
    unit = _unit_hint(tl)
    for attr, entity, name, rgba in L.DRIFT_SERIES:
        series = getattr(tl, attr)
        if series is not None:
            name = tl.labels.drift if attr == "time_aligned_drift" else name  # an episode's tracking error
            if attr != "time_aligned_drift" and _same(series, tl.time_aligned_drift):
                name += " (= time-aligned: drawn on top of it)"  # else one line seems to be missing
            log_series(rec, entity, steps, series, indexes_for, f"{name} [{unit}]", rgba)
    if tl.joint_error is not None:
        for j, joint in enumerate(JOINT_NAMES):
            log_series(rec, f"{L.JOINT_ERROR}/{joint}", steps, tl.joint_error[:, j], indexes_for,
                       joint, L.JOINT_RGBA[joint])
    if tl.ee_error_mm is not None:
        log_series(rec, L.EE_ERROR, steps, tl.ee_error_mm, indexes_for, "tool-point error [mm]",
                   (214, 39, 40, 255))
    if tl.chunk_rmse is not None:
        log_series(rec, L.CHUNK_RMSE, tl.chunk_start_step, tl.chunk_rmse, indexes_for,
                   f"chunk RMSE [{unit}]", (31, 119, 180, 255), points=True)
    log_joint_values(rec, tl, indexes_for)


def log_joint_values(rec: rr.RecordingStream, tl: RolloutTimeline, indexes_for: IndexesFor) -> None:
    """Per joint: predicted and GT values, its two limits, and a marker at every violating step."""
    steps = np.arange(tl.n_steps)
    ends = np.array([0, tl.n_steps - 1])
    for j, joint in enumerate(JOINT_NAMES):
        log_series(rec, L.joint_plot(joint, "pred"), steps, tl.pred[:, j], indexes_for,
                   f"{joint} {tl.labels.pred}", L.PRED_RGBA)
        if tl.gt_aligned is not None:
            log_series(rec, L.joint_plot(joint, "gt"), steps, tl.gt_aligned[:, j], indexes_for,
                       f"{joint} {tl.labels.gt}", L.GT_RGBA)
        for k, side in enumerate(("lower_limit", "upper_limit")):
            log_series(rec, L.joint_plot(joint, side), ends, np.full(2, tl.limits[j, k]), indexes_for,
                       f"{joint} {side.replace('_', ' ')}", (120, 120, 120, 255), width=1.0)
        bad = np.flatnonzero(tl.limit_violation[:, j])
        log_series(rec, L.joint_plot(joint, "limit_violation"), bad, tl.pred[bad, j], indexes_for,
                   f"{joint} past its limit", L.LIMIT_RGBA, points=True, marker="cross", marker_size=5.0)


def log_psnr(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, psnr_db: npt.NDArray[np.float64],
             frame_indexes_for: IndexesFor, rgba: Sequence[int]) -> int:
    """PSNR [dB] of ``view`` per imagined frame (frames without GT left out)."""
    return log_series(rec, L.psnr_path(view), np.arange(len(psnr_db)), psnr_db, frame_indexes_for,
                      f"{view} PSNR [dB]", rgba)


def log_video_action(rec: rr.RecordingStream, va: VideoAction, frame_indexes_for: IndexesFor,
                     rgba: Sequence[int]) -> int:
    """Video-action agreement of one view per imagined frame: the video's and the joints' GT time
    [s], their lag, and a marker where they part (frames without a match left out)."""
    frames = np.arange(va.video_gt_s.size)
    n = log_series(rec, L.gt_time_path(va.view, "video"), frames, va.video_gt_s, frame_indexes_for,
                   f"{va.view} video's GT time [s]", rgba, points=True, marker_size=2.5)
    lag = va.lag_s
    if va.joints_gt_s is None or lag is None:
        return n
    log_series(rec, L.gt_time_path(va.view, "joints"), frames, va.joints_gt_s, frame_indexes_for,
               "joints' GT time [s]", L.PRED_RGBA)
    # a frame without a lag, drawn where the side that has a GT time has it (0 where neither has)
    missing = np.flatnonzero(~np.isfinite(lag))
    at = np.where(np.isfinite(va.joints_gt_s), va.joints_gt_s, np.where(np.isfinite(va.video_gt_s), va.video_gt_s, 0.0))
    log_series(rec, L.gt_time_path(va.view, "no_match"), missing, at[missing], frame_indexes_for,
               f"{va.view}: {NO_MATCH} (no lag)", L.NO_MATCH_RGBA, points=True, marker="cross", marker_size=3.0)
    if va.frozen():  # no lag to plot: the GT times show the still video beside the moving joints
        log_series(rec, L.lag_path(va.view), [], [], frame_indexes_for,
                   f"{va.view} lag: video {FROZEN}, no lag", rgba, points=True, marker_size=2.5)
        rec.send_columns(L.EVENTS, frame_indexes_for(np.array([0])), rr.TextLog.columns(
            text=[f"{va.view}: {frozen_note(va)}"], level=["WARN"]))
        return n
    log_series(rec, L.lag_path(va.view), frames, lag, frame_indexes_for,
               f"{va.view} lag, video - joints [s]", rgba, points=True, marker_size=2.5)
    split = va.split_chunk()
    if split is not None:
        first = int(np.flatnonzero(va.frame_chunk >= split)[0])
        log_series(rec, L.gt_time_path(va.view, "split"), [first], [va.joints_gt_s[first]], frame_indexes_for,
                   f"{va.view}: video and actions part (chunk {split})", L.LIMIT_RGBA, points=True,
                   marker="diamond", marker_size=8.0)
    return n


def log_markers(rec: rr.RecordingStream, tl: RolloutTimeline, indexes_for: IndexesFor) -> None:
    """Chunk starts as text events (the ``chunk`` timeline steps through them; drawn in the
    plots, 60 of them read as a grey band of data at y = 0), and the episode's end: a marker in
    every plot and an event."""
    starts = np.minimum(tl.chunk_start_step, tl.n_steps - 1)
    texts = [f"chunk {k} starts (step {s}, {tl.t_s[s]:.2f} s)" for k, s in enumerate(starts)]
    rec.send_columns(L.EVENTS, indexes_for(starts), rr.TextLog.columns(text=texts, level=["INFO"] * len(texts)))
    end = tl.episode_end_step
    if end is not None and end < tl.n_steps:
        log_series(rec, f"{L.MARKERS}/episode_end", [end], [0.0], indexes_for, "real episode ends",
                   L.LIMIT_RGBA, points=True, marker="diamond", marker_size=8.0)
        rec.send_columns(L.EVENTS, indexes_for(np.array([end])), rr.TextLog.columns(
            text=[f"the real episode ends at step {end} ({tl.t_s[end]:.2f} s): "
                  "later steps are post-episode"], level=["WARN"]))


def _same(a: npt.ArrayLike | None, b: npt.ArrayLike | None) -> bool:
    return a is not None and b is not None and np.allclose(a, b, rtol=0, atol=1e-9)


def _unit_hint(tl: RolloutTimeline) -> str:
    return "deg, gripper 0..100" if tl.units.arm == "degrees" else "-100..100, gripper 0..100"
