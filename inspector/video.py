"""Video in and out through PyAV: decode whole clips once, encode H.264 that any viewer plays.

Everything that reads a frame goes through :class:`VideoClip`, so frames are decoded once and
served from memory afterwards (a scrub step never re-decodes).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .errors import InspectorError


@dataclass
class VideoInfo:
    """What a video file says about itself (read from the container, nothing decoded)."""

    path: Path
    codec: str
    width: int
    height: int
    fps: float
    n_frames: int  # container's count; 0 when the container does not say


def probe(path: str | Path) -> VideoInfo:
    """Read codec, size, fps and frame count without decoding.

    Raises:
        InspectorError: the file is missing or not a readable video.
    """
    import av

    path = Path(path)
    if not path.is_file():
        raise InspectorError(path, "video file not found")
    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                raise InspectorError(path, "no video stream")
            stream = container.streams.video[0]
            fps = float(stream.average_rate or stream.guessed_rate or 0)
            return VideoInfo(path, stream.codec_context.name, stream.width, stream.height, fps,
                             int(stream.frames or 0))
    except InspectorError:
        raise
    except Exception as exc:  # PyAV raises many types for a broken file
        raise InspectorError(path, f"cannot read video ({type(exc).__name__}: {exc})") from None


def decode(path: str | Path, start_s: float | None = None, end_s: float | None = None,
           size: tuple[int, int] | None = None,
           ) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float64]]:
    """Decode frames to RGB, optionally only those with ``start_s <= pts < end_s``.

    Args:
        path: the video file.
        start_s, end_s: time window [s] in the file's own timeline (for LeRobot v3.0 files that
            hold many episodes); None for the whole file.
        size: (width, height) to scale every frame to while decoding (swscale, area filter),
            e.g. a 640x480 GT video to a 320x176 imagined one; None keeps the file's size.

    Returns:
        (frames, times): (N, H, W, 3) uint8 and (N,) presentation times [s].

    Raises:
        InspectorError: missing, not a video, or undecodable.
    """
    import av
    from av.video.reformatter import VideoReformatter

    path = Path(path)
    if not path.is_file():
        raise InspectorError(path, "video file not found")
    buffer: npt.NDArray[np.uint8] | None = None
    extra: list[npt.NDArray[np.uint8]] = []
    times: list[float] = []
    # half a frame of slack: container timestamps are rounded to the time base
    try:
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            stream.thread_type = "AUTO"
            # One reformatter for the clip: it keeps its swscale context, where frame.to_ndarray()
            # builds a new one per frame (4x the cost of decoding at these sizes).
            reformatter = VideoReformatter()
            # a window (one episode of a multi-episode file) holds an unknown share of the frames
            expected = int(stream.frames or 0) if start_s is None and end_s is None else 0
            fps = float(stream.average_rate or 30)
            slack = 0.5 / fps
            if start_s is not None and start_s > 1.0:
                container.seek(int(max(0.0, start_s - 1.0) / stream.time_base), stream=stream,
                               backward=True, any_frame=False)
            for frame in container.decode(stream):
                t = float(frame.pts * stream.time_base) if frame.pts is not None else len(times) / fps
                if start_s is not None and t < start_s - slack:
                    continue
                if end_s is not None and t >= end_s - slack:
                    break
                width, height = size if size is not None else (frame.width, frame.height)
                rgb = reformatter.reformat(frame, width=width, height=height, format="rgb24",
                                           interpolation="AREA")
                image = rgb.to_ndarray()
                n = len(times)
                if n == 0 and expected > 0:
                    # the container's frame count sizes the clip once: no list + stack copy,
                    # which would hold every clip twice at its peak
                    buffer = np.empty((expected, *image.shape), np.uint8)
                if buffer is not None and n < len(buffer):
                    buffer[n] = image
                else:
                    extra.append(image)  # more frames than the container announced
                times.append(t)
    except Exception as exc:
        raise InspectorError(path, f"cannot decode video ({type(exc).__name__}: {exc})") from None
    if not times:
        raise InspectorError(path, "video has no decodable frames"
                             + (f" in [{start_s:.3f}, {end_s:.3f}) s" if start_s is not None else ""))
    if buffer is None:
        frames = np.stack(extra)
    elif extra:
        frames = np.concatenate([buffer, np.stack(extra)])
    else:
        frames = buffer[: len(times)]
    return frames, np.asarray(times)


class VideoClip:
    """A clip decoded once on first use, then served from memory.

    Args:
        path: the video file.
        start_s, end_s: optional window [s] inside the file.
        size: optional (width, height) to decode to.
    """

    def __init__(self, path: str | Path, start_s: float | None = None, end_s: float | None = None,
                 size: tuple[int, int] | None = None):
        self.path = Path(path)
        self._window = (start_s, end_s)
        self._size = size
        self._frames: npt.NDArray[np.uint8] | None = None
        self._times: npt.NDArray[np.float64] | None = None

    def load(self) -> "VideoClip":
        if self._frames is None:
            self._frames, self._times = decode(self.path, *self._window, size=self._size)
        return self

    @property
    def frames(self) -> npt.NDArray[np.uint8]:
        """(N, H, W, 3) uint8 RGB."""
        return self.load()._frames  # type: ignore[return-value]

    @property
    def times(self) -> npt.NDArray[np.float64]:
        """(N,) frame times [s] relative to the start of the window."""
        t = self.load()._times
        return t - (self._window[0] or 0.0)  # type: ignore[operator]

    def __len__(self) -> int:
        return len(self.frames)

    def frame(self, index: int) -> npt.NDArray[np.uint8]:
        """Frame ``index``, clamped into the clip (a rollout may outlast its GT video)."""
        return self.frames[int(np.clip(index, 0, len(self.frames) - 1))]

    def frame_at(self, t_s: float) -> npt.NDArray[np.uint8]:
        """The frame showing at time ``t_s`` [s] from the start of the clip."""
        i = int(np.searchsorted(self.times, t_s + 1e-6, side="right")) - 1
        return self.frame(max(i, 0))


def encode_h264(path: str | Path, frames: npt.NDArray[np.uint8], fps: float, crf: int = 23) -> None:
    """Write (N, H, W, 3) uint8 RGB frames as H.264 (yuv420p) MP4, atomically.

    Odd sizes are padded to even (yuv420p needs it). The file appears complete or not at all.
    """
    import av

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n, h, w, _ = frames.shape
    pad_h, pad_w = h % 2, w % 2
    if pad_h or pad_w:
        frames = np.pad(frames, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}.mp4")
    try:
        with av.open(str(tmp), mode="w") as container:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            stream.width, stream.height = w + pad_w, h + pad_h
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": str(crf), "preset": "medium"}
            for image in frames:
                for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")):
                    container.mux(packet)
            for packet in stream.encode():
                container.mux(packet)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
