"""Rerun ``.rrd`` export of a rollout: the same timeline the app shows, as a self-explaining file.

Usage::

    from inspector.export.recording import write_recording
    from inspector.analysis.timeline import build_timeline

    write_recording(build_timeline(rollout), "ep000.rrd", views=["front"],
                    progress=lambda fraction, message: print(f"{fraction:.0%} {message}"))

A recording holds the timelines ``time`` (s), ``frame`` (imagined frame) and ``chunk``; the GT and
predicted arms from our URDF (:mod:`inspector.export.arms`); the imagined and GT videos as
H.264 assets with frame references (:mod:`inspector.export.video`); every metric as a named
series with markers at chunk starts, the episode's end and limit violations
(:mod:`inspector.export.series`); a markdown description (:mod:`inspector.export.description`);
and one default blueprint (:func:`inspector.export.layout.build_blueprint`). Files are written to
a temporary sibling and renamed into place, so a failed export never leaves half a file.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import cast

import numpy as np
import rerun as rr

from ..analysis.measure_settings import DEFAULT_MEASURES, MeasureSettings
from ..analysis.timeline import RolloutTimeline, build_timeline
from ..cache import rollout_key
from ..data.session import ROLLOUT_FILE
from ..errors import InspectorError
from ..robot.description import VIEW_DIRECTION, bounding_sphere
from ..robot.kinematics import kinematics
from ..rows.entries import read_entry, write_entry
from . import layout as L
from .arms import log_arms, prepare_meshes
from .cameras import log_camera, recording_cameras
from .description import describe
from .files import RRD_SUFFIX as RRD_SUFFIX
from .files import format_size as format_size
from .outcomes import log_outcomes
from .sanity_series import log_sanity
from .series import log_markers, log_metric_series, log_psnr, log_video_action
from .video import Progress, frame_indexes, log_view

# Share of the progress bar each stage takes (decoding for PSNR dominates a cold export).
_VIDEO_METRICS = (0.02, 0.70)
_VIDEO_ASSETS = (0.85, 0.99)


def write_recording(timeline: RolloutTimeline, path: str | Path, views: Sequence[str] | None = None,
                    progress: Callable[[float, str], None] | None = None,
                    outcome_source: str | None = None) -> Path:
    """Write ``timeline`` as a Rerun recording at ``path`` (atomically).

    Args:
        timeline: the rollout's computed timeline (:func:`inspector.analysis.timeline.build_timeline`).
        path: the ``.rrd`` file to write; its directory is created if needed.
        views: camera views to include (default: every imagined and GT view).
        progress: ``progress(fraction, message)``, called as the export advances (0 -> 1).
        outcome_source: the outcome source whose success and progress the series show
            (``--outcome-source``; None: a label over a file over sim/recording).

    Returns:
        ``path``.

    Raises:
        InspectorError: a requested view does not exist, or a video is unreadable.
    """
    path = Path(path)
    report = progress or (lambda fraction, message: None)
    views = select_views(timeline, views)
    report(0.0, "video metrics")
    with ThreadPoolExecutor(max_workers=1) as meshes:
        meshes_ready = meshes.submit(prepare_meshes)
        psnr = compute_psnr(timeline, views, report)
        meshes_ready.result()  # re-raises what went wrong there
    contents = L.Contents(
        views={v: (v in timeline.rollout.views, v in timeline.gt.views) for v in views},
        gt_joints=timeline.has_gt_joints,
        psnr_views=[v for v, series in psnr.items() if np.isfinite(series).any()],
        agreement_views=[v for v in psnr if timeline.video_action(v) is not None],
        pred_name=timeline.labels.pred, gt_name=timeline.labels.gt, chunks=timeline.n_chunks > 1,
        eye=eye_fitting(timeline) if timeline.has_joints else L.Contents.eye,
        joints=timeline.has_joints,
        cameras=[v for v, c in recording_cameras(timeline, views).items() if c.is_fixed or timeline.has_joints],
    )
    # Encoded in memory (a few MB) and written by us: a write error (disk full, permission) is
    # then an ordinary OSError naming the file, not a log line from rerun's writer thread.
    rec = rr.RecordingStream(application_id=application_id(timeline.tag))
    stream = rec.binary_stream()  # type: ignore[misc]  # rerun binds a module function as this method
    try:
        # Active, not only default: in this stream the layout follows the recording's first
        # message, and a viewer that has already laid the recording out by heuristics keeps that
        # layout over a mere default (Rerun's web viewer does).
        rec.send_blueprint(L.build_blueprint(contents), make_active=True, make_default=True)
        session = timeline.rollout.session
        rec.send_recording_name(f"{session.name}/{timeline.tag}" if session is not None else timeline.tag)
        _log_recording(rec, timeline, views, psnr, report, outcome_source)
        data = stream.read() or b""
    except BaseException:
        # A failed recording is dropped by us: what was logged is taken out of the stream, so
        # disconnecting drops nothing (rerun would log that drop on stderr, after our error line).
        with contextlib.suppress(Exception):
            stream.read()
        raise
    finally:
        rec.disconnect()
    write_file_atomic(path, data)
    report(1.0, "done")
    return path


def eye_fitting(tl: RolloutTimeline) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """The 3D view's (position, look target): every tool path and every chunk's horizon in view
    (a wandering prediction used to run off the top), seen from the front right, above."""
    points = [tl.ee_pred, kinematics().gripper_positions(tl.chunks.reshape(-1, tl.chunks.shape[-1]), tl.units),
              np.zeros((1, 3)), np.array([[0.0, 0.0, 0.3]])]  # the base, and the arm's own height
    if tl.ee_gt is not None:
        points.append(tl.ee_gt)
    centre, radius = bounding_sphere(np.concatenate(points))
    distance = radius / np.tan(np.radians(55) / 2) * 1.1  # within the viewer's default field of view
    eye = centre + np.asarray(VIEW_DIRECTION) * distance
    return (tuple(float(v) for v in eye), tuple(float(v) for v in centre))  # type: ignore[return-value]


def write_file_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary sibling, so that ``path`` is either the old
    file or the complete new one; a write error leaves no temporary file.

    Raises:
        InspectorError: the file cannot be written (no space left, permission denied, ...).
    """
    tmp = path.with_name(f".{path.name[:64]}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "xb") as fh:  # the usual umask-derived mode, unlike mkstemp's 0600
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InspectorError(exc.filename if exc.filename and exc.filename != str(tmp) else path,
                             f"cannot write the recording ({exc.strerror or exc})") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _log_recording(rec: rr.RecordingStream, tl: RolloutTimeline, views: list[str],
                   psnr: dict[str, np.ndarray], report: Callable[[float, str], None],
                   outcome_source: str | None = None) -> None:
    """Orchestrates the ``log_*`` functions; each takes the stream and the timeline."""
    def steps_indexes(steps: np.ndarray) -> list[rr.TimeColumn]:
        return L.step_indexes(tl, steps)

    def frames_indexes(frames: np.ndarray) -> list[rr.TimeColumn]:
        return frame_indexes(tl, frames)

    report(_VIDEO_METRICS[1], "arms")
    mean_psnr = {v: (float(np.nanmean(s)) if np.isfinite(s).any() else None) for v, s in psnr.items()}
    agreements = {v: va for v in psnr if (va := tl.video_action(v)) is not None}
    rec.log(L.DESCRIPTION, rr.TextDocument(describe(tl, mean_psnr, agreements), media_type="text/markdown"),
            static=True)
    log_outcomes(rec, tl, steps_indexes, outcome_source)  # did the task succeed, by each source's account
    if tl.has_joints:  # a video-only rollout has no arm, no joint series
        log_arms(rec, tl, steps_indexes(np.arange(tl.n_steps)))
        report(0.80, "metric series")
        log_metric_series(rec, tl, steps_indexes)
    log_markers(rec, tl, steps_indexes)
    log_sanity(rec, tl, steps_indexes)
    for i, (view, series) in enumerate(psnr.items()):
        log_psnr(rec, tl, view, series, frames_indexes, L.VIEW_RGBA[i % len(L.VIEW_RGBA)])
        if view in agreements:
            log_video_action(rec, agreements[view], frames_indexes, L.VIEW_RGBA[i % len(L.VIEW_RGBA)])
    # each view with a camera is a pinhole in the scene, its frames under it (a riding camera is
    # posed by the predicted arm: none without joints)
    cameras = {v: c for v, c in recording_cameras(tl, views).items() if c.is_fixed or tl.has_joints}
    for view, camera in cameras.items():
        log_camera(rec, tl, view, camera, steps_indexes)
    lo, hi = _VIDEO_ASSETS
    with tempfile.TemporaryDirectory(prefix="inspector-video-") as tmp:
        for i, view in enumerate(views):
            start, span = lo + (hi - lo) * i / len(views), (hi - lo) / len(views)
            report(start, f"video {view}")
            log_view(rec, tl, view, Path(tmp),
                     progress=cast(Progress, lambda f, v=view, s=start: report(s + span * f, f"encoding GT video {v}")),
                     under_camera=view in cameras)


def application_id(tag: str) -> str:
    """Rerun application id of a rollout's recording: one per rollout, so each file opens with
    its own default blueprint (the viewer keeps one active blueprint per application)."""
    return "inspector_" + re.sub(r"[^A-Za-z0-9_-]", "_", tag)


def select_views(tl: RolloutTimeline, views: Sequence[str] | None) -> list[str]:
    """The views to export: ``views`` checked against the rollout's (default: all of them)."""
    available = list(tl.rollout.views) + [v for v in tl.gt.views if v not in tl.rollout.views]
    if views is None:
        return available
    missing = [v for v in views if v not in available]
    if missing:
        raise InspectorError(tl.rollout.root / ROLLOUT_FILE,
                             f"no view {missing[0]!r} in rollout {tl.tag!r}; views: {available}")
    return list(dict.fromkeys(views))


def compute_psnr(tl: RolloutTimeline, views: Sequence[str],
                 report: Callable[[float, str], None]) -> dict[str, np.ndarray]:
    """(F,) PSNR [dB] per view with imagined and GT frames (the timeline's own, cached metric).

    A timeline that already holds the metric (the app's) returns at once.
    """
    lo, hi = _VIDEO_METRICS
    metrics_by_view = tl.all_video_metrics(list(views), lambda f, msg: report(lo + (hi - lo) * f, msg))
    return {view: vm.psnr_db for view, vm in metrics_by_view.items()}


@contextlib.contextmanager
def cached_video_metrics(tl: RolloutTimeline, cache) -> Iterator[None]:
    """Give ``tl`` the video metrics the metrics cache holds for it; keep the ones computed
    meanwhile there (a rollout the app or ``report`` has seen exports without decoding)."""
    key = rollout_key(tl.rollout, tl.gt, tl.limit_margin_deg, tl.measures)
    cached = read_entry(cache, key)
    known = {v: vm for v, vm in cached.video.items() if v in tl.video_views()}
    for vm in known.values():
        tl.set_video_metrics(vm)
    yield
    new = {v: vm for v, vm in tl.known_video_metrics().items() if v not in known}
    if new:
        write_entry(cache, key, cached.row, {**known, **new})


def export_rollout(rollout, dest: Path, views: Sequence[str] | None, limit_margin_deg: float, cache,
                   progress: Callable[[float, str], None] | None = None,
                   outcome_source: str | None = None, measures: MeasureSettings = DEFAULT_MEASURES) -> Path:
    """Write one rollout's recording at ``dest``: its timeline, with video metrics through
    ``cache`` (:class:`inspector.cache.MetricsCache`); of ``views``, those it has (default: all);
    its outcome as ``outcome_source`` has it (None: the precedence rule)."""
    tl = build_timeline(rollout, limit_margin_deg=limit_margin_deg, measures=measures)
    rollout_views = None if views is None else [v for v in views if v in tl.rollout.views or v in tl.gt.views]
    with cached_video_metrics(tl, cache):
        return write_recording(tl, dest, views=rollout_views, progress=progress, outcome_source=outcome_source)
