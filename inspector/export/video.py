"""Imagined and GT video in a recording: one ``AssetVideo`` per clip plus a frame reference per frame.

Frames are never logged as images. An H.264 file is embedded as it is, never decoded; anything
else (an AV1 dataset video, a v3.0 file holding many episodes) is streamed into a new H.264 file,
frame by frame, holding only the frames the rollout shows. Each reference sits at the time of
the imagined frame it pairs with, exactly as the app and the metrics pair them
(:meth:`RolloutTimeline.gt_index_of_frame`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
import rerun as rr

from ..analysis.timeline import RolloutTimeline
from ..data.video import ForwardReader, encode_h264, probe
from ..errors import InspectorError
from . import layout as L
from .cameras import log_camera_frames

PLAYABLE_CODECS = ("h264",)
Progress = Callable[[float], None]


def log_view(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, work_dir: Path,
             progress: Progress | None = None, under_camera: bool = False) -> tuple[int, int]:
    """Log ``view``'s imagined and GT clips. Returns (imagined frames, GT frames) referenced.

    ``under_camera``: the view has a camera in the scene; its frames are referenced under it too
    (:mod:`inspector.export.cameras`), where Rerun projects the arms into them."""
    n_imagined = log_imagined(rec, tl, view, work_dir, under_camera) if view in tl.rollout.views else 0
    n_gt = 0
    if view in tl.gt.views:
        # a GT-only view (a dataset camera the model does not imagine) follows the imagined
        # frames the rollout would have
        n_frames = n_imagined or tl.n_chunks * tl.rollout.frames_per_chunk
        n_gt = log_gt(rec, tl, view, work_dir, n_frames, progress, under_camera)
    return n_imagined, n_gt


def log_imagined(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, work_dir: Path,
                 under_camera: bool = False) -> int:
    src = tl.rollout.video_path(view)
    if probe(src).codec not in PLAYABLE_CODECS:
        src = _reencode((rgb for _, rgb in tl.rollout.video(view).iter_frames()), tl.fps,
                        work_dir / f"{view}_imagined.mp4")
    asset = rr.AssetVideo(path=src)
    timestamps = asset.read_frame_timestamps_nanos()
    entity = L.video_path(view, "imagined")
    rec.log(entity, asset, static=True)
    rec.send_columns(entity, frame_indexes(tl, np.arange(len(timestamps))),
                     rr.VideoFrameReference.columns_nanos(timestamps))
    if under_camera:
        log_camera_frames(rec, view, "imagined", frame_indexes(tl, np.arange(len(timestamps))), timestamps)
    return len(timestamps)


def log_gt(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, work_dir: Path,
           n_imagined: int, progress: Progress | None = None, under_camera: bool = False) -> int:
    """GT of ``view``: a carried H.264 clip as it is (frame i pairs with imagined frame i), else
    the episode frames paired with each imagined frame, streamed into a new H.264 asset."""
    clip = tl.gt.clips[view]
    if tl.gt.carried and probe(clip.path).codec in PLAYABLE_CODECS:
        asset = rr.AssetVideo(path=clip.path)
        timestamps = asset.read_frame_timestamps_nanos()
        shown = np.arange(min(len(timestamps), n_imagined))
        timestamps = timestamps[shown]
    else:
        index_of = tl.gt_index_of_frame(view)
        shown = np.array([f for f in range(n_imagined) if index_of(f) >= 0], dtype=np.int64)
        if shown.size == 0:
            return 0
        reader = ForwardReader(clip)

        def paired() -> Iterator[npt.NDArray[np.uint8]]:
            for i, f in enumerate(shown):
                frame = reader.frame_at(index_of(int(f)))
                if frame is None:
                    raise InspectorError(clip.path, f"no GT frame {index_of(int(f))} for imagined frame {f}")
                if progress is not None and i % 32 == 0:
                    progress(i / len(shown))
                yield frame

        path = _reencode(paired(), tl.fps, work_dir / f"{view}_gt.mp4")
        asset = rr.AssetVideo(path=path)
        timestamps = asset.read_frame_timestamps_nanos()
    entity = L.video_path(view, "gt")
    rec.log(entity, asset, static=True)
    rec.send_columns(entity, frame_indexes(tl, shown), rr.VideoFrameReference.columns_nanos(timestamps))
    if under_camera:
        log_camera_frames(rec, view, "gt", frame_indexes(tl, shown), timestamps)
    return len(shown)


def frame_indexes(tl: RolloutTimeline, frames: npt.NDArray[np.int64]) -> list[rr.TimeColumn]:
    """Timeline columns of imagined frames: the time and chunk of the step each one shows."""
    frames = np.asarray(frames, dtype=np.int64)
    n = int(frames.max()) + 1 if frames.size else 0
    steps = tl.frame_step(n)[frames] if n else frames
    return [
        rr.TimeColumn(L.TIME, duration=tl.t_s[steps]),
        rr.TimeColumn(L.FRAME, sequence=frames),
        rr.TimeColumn(L.CHUNK, sequence=tl.step_chunk[steps]),
    ]


def _reencode(frames: Iterable[npt.NDArray[np.uint8]], fps: float, dest: Path) -> Path:
    """RGB frames, streamed -> H.264 MP4 at ``dest`` (fast preset: the asset only has to play)."""
    encode_h264(dest, frames, fps, preset="veryfast")
    return dest
