"""Imagined and GT video in a recording: one ``AssetVideo`` per clip plus a frame reference per frame.

Frames are never logged as images. An H.264 file is embedded as it is; anything else (an AV1
dataset video, a v3.0 file holding many episodes) is re-encoded to H.264 first, holding only
the frames the rollout shows. Each reference sits at the time of the imagined frame it pairs
with, exactly as the app pairs them (:meth:`GroundTruth.frame`).
"""

from __future__ import annotations

import os
import tempfile
from fractions import Fraction
from pathlib import Path
from typing import Callable

import numpy as np
import numpy.typing as npt
import rerun as rr

from . import export_layout as L
from .timeline import RolloutTimeline
from .video import VideoClip, probe

PLAYABLE_CODECS = ("h264",)
Progress = Callable[[float], None]


def log_view(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, work_dir: Path,
             progress: Progress | None = None) -> tuple[int, int]:
    """Log ``view``'s imagined and GT clips. Returns (imagined frames, GT frames) referenced."""
    n_imagined = log_imagined(rec, tl, view, work_dir) if view in tl.rollout.views else 0
    n_gt = 0
    if view in tl.gt.views:
        # a GT-only view (a dataset camera the model does not imagine) follows the imagined
        # frames the rollout would have
        n_frames = n_imagined or tl.n_chunks * tl.rollout.frames_per_chunk
        n_gt = log_gt(rec, tl, view, work_dir, n_frames, progress)
    return n_imagined, n_gt


def log_imagined(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, work_dir: Path) -> int:
    src = tl.rollout.video_path(view)
    if probe(src).codec not in PLAYABLE_CODECS:
        src = _reencode(tl.rollout.video(view).frames, tl.fps, work_dir / f"{view}_imagined.mp4")
    asset = rr.AssetVideo(path=src)
    timestamps = asset.read_frame_timestamps_nanos()
    entity = L.video_path(view, "imagined")
    rec.log(entity, asset, static=True)
    rec.send_columns(entity, frame_indexes(tl, np.arange(len(timestamps))),
                     rr.VideoFrameReference.columns_nanos(timestamps))
    return len(timestamps)


def log_gt(rec: rr.RecordingStream, tl: RolloutTimeline, view: str, work_dir: Path,
           n_imagined: int, progress: Progress | None = None) -> int:
    """GT of ``view``: a carried H.264 clip as it is (frame i pairs with imagined frame i), else
    the episode frames paired with each imagined frame, encoded to a new H.264 asset."""
    clip = tl.gt.clips[view]
    if isinstance(clip, VideoClip) and probe(clip.path).codec in PLAYABLE_CODECS:
        asset = rr.AssetVideo(path=clip.path)
        timestamps = asset.read_frame_timestamps_nanos()
        shown = np.arange(min(len(timestamps), n_imagined))
        timestamps = timestamps[shown]
    else:
        steps = tl.frame_step(n_imagined)
        pairs = [(f, tl.gt.frame(view, f, int(steps[f]))) for f in range(n_imagined)]
        pairs = [(f, g) for f, g in pairs if g is not None]
        if not pairs:
            return 0
        shown = np.array([f for f, _ in pairs])
        path = _reencode(np.stack([g for _, g in pairs]), tl.fps, work_dir / f"{view}_gt.mp4", progress)
        asset = rr.AssetVideo(path=path)
        timestamps = asset.read_frame_timestamps_nanos()
    entity = L.video_path(view, "gt")
    rec.log(entity, asset, static=True)
    rec.send_columns(entity, frame_indexes(tl, shown), rr.VideoFrameReference.columns_nanos(timestamps))
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


def _reencode(frames: npt.NDArray[np.uint8], fps: float, dest: Path,
              progress: Progress | None = None) -> Path:
    """(N, H, W, 3) uint8 -> H.264 MP4 at ``dest`` (fast preset: the asset only has to play)."""
    import av

    n, h, w, _ = frames.shape
    if h % 2 or w % 2:
        frames = np.pad(frames, ((0, 0), (0, h % 2), (0, w % 2), (0, 0)), mode="edge")
    fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".mp4", dir=dest.parent)
    os.close(fd)
    try:
        with av.open(tmp, mode="w") as container:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            stream.width, stream.height = frames.shape[2], frames.shape[1]
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": "23", "preset": "veryfast"}
            for i, image in enumerate(frames):
                frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")
                container.mux(stream.encode(frame))
                if progress is not None and i % 32 == 0:
                    progress(i / n)
            container.mux(stream.encode())
        os.replace(tmp, dest)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return dest
