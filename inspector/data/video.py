"""Video in and out through PyAV, frame by frame: memory follows one frame, never a whole clip.

A :class:`VideoClip` names frames on disk (a file, or a time window of it: LeRobot v3.0 files hold
many episodes); it holds no pixels. Readers stream (:meth:`VideoClip.iter_frames`), decoding
each frame straight to the size the caller wants (swscale, area filter), so a 2560x1440 source
shown at 320x180 never exists in memory at full size for more than one frame. Only
:func:`decode` returns a whole clip, for small clips, and refuses one past its byte budget with
a one-line error instead of exhausting the machine.
"""

from __future__ import annotations

import io
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from ..errors import InspectorError

if TYPE_CHECKING:
    import av  # PyAV loads on first decode (see probe)

# The largest source frame decoded at all [pixels]: 8K UHD. A header claiming more is refused
# before a frame is allocated.
MAX_SOURCE_PIXELS = 7680 * 4320
# What :func:`decode` may hold for one clip [bytes].
DECODE_BUDGET_BYTES = 512 * 1024 * 1024
# FFmpeg's threading for each decoder: "AUTO" decodes ahead on the other cores; a process that
# already runs one worker per core (``report --jobs``) sets "NONE"; None leaves FFmpeg's default.
DECODE_THREADS: str | None = "AUTO"


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


Size = tuple[int, int]  # (width, height) [px]


def fit_size(width: int, height: int, max_width: int, max_height: int | None = None) -> Size:
    """(width, height) scaled down (never up) to fit ``max_width`` x ``max_height``, even sides."""
    scale = min(1.0, max_width / max(1, width), (max_height or height) / max(1, height))
    return max(2, int(round(width * scale / 2)) * 2), max(2, int(round(height * scale / 2)) * 2)


class RgbConverter:
    """Decoded frames -> (H, W, 3) uint8 RGB at any size, through one swscale context per size
    (``frame.to_ndarray()`` builds a new context per frame: 4x the cost of decoding)."""

    def __init__(self) -> None:
        from av.video.reformatter import VideoReformatter

        self._reformatter = VideoReformatter()

    def __call__(self, frame, size: Size | None = None) -> npt.NDArray[np.uint8]:
        width, height = size if size is not None else (frame.width, frame.height)
        if (width, height) == (frame.width, frame.height):
            # No scaling: the same pixels by any filter, and swscale's fast unscaled path is 3x
            # quicker than the area filter's (the largest cost of a report's video metrics).
            return cast(npt.NDArray[np.uint8], self._reformatter.reformat(frame, format="rgb24").to_ndarray())
        return cast(npt.NDArray[np.uint8],  # rgb24 frames are uint8
                    self._reformatter.reformat(frame, width=width, height=height, format="rgb24",
                                               interpolation="AREA").to_ndarray())


@dataclass(frozen=True)
class VideoClip:
    """Frames of a video file, optionally a time window of it. Holds no pixels.

    Attributes:
        path: the video file.
        start_s, end_s: window [s] in the file's own timeline, ``start_s <= pts < end_s``; None
            for the file's start / end. Frame indexes count from the window's first frame.
    """

    path: Path
    start_s: float | None = None
    end_s: float | None = None

    @property
    def key(self) -> tuple[str, float | None, float | None]:
        """Identity for caches: two clips with the same key show the same frames."""
        return (str(self.path), self.start_s, self.end_s)

    def info(self) -> VideoInfo:
        return probe(self.path)

    def iter_frames(self, size: Size | None = None, start: int = 0
                    ) -> Iterator[tuple[int, npt.NDArray[np.uint8]]]:
        """Stream (index, (H, W, 3) uint8 RGB) frame by frame, from frame ``start`` on.

        Args:
            size: (width, height) to scale every frame to while decoding; None keeps the file's.
            start: first frame wanted (the decoder seeks to the keyframe before it).

        Raises:
            InspectorError: missing, not a video, undecodable, or frames larger than
                :data:`MAX_SOURCE_PIXELS`.
        """
        to_rgb = RgbConverter()
        for index, frame in self.iter_decoded(start):
            yield index, to_rgb(frame, size)

    def iter_decoded(self, start: int = 0) -> Iterator[tuple[int, av.VideoFrame]]:
        """Stream (index, decoded ``av.VideoFrame``): for callers that want one frame at several
        sizes (:class:`RgbConverter`). Raises as :meth:`iter_frames`."""
        import av

        if not self.path.is_file():
            raise InspectorError(self.path, "video file not found")
        try:
            with av.open(str(self.path)) as container:
                if not container.streams.video:
                    raise InspectorError(self.path, "no video stream")
                stream = container.streams.video[0]
                if DECODE_THREADS:
                    stream.thread_type = DECODE_THREADS
                if stream.width * stream.height > MAX_SOURCE_PIXELS:
                    raise InspectorError(self.path, f"frames of {stream.width}x{stream.height} exceed the "
                                                    f"{MAX_SOURCE_PIXELS:,}-pixel limit")
                fps = float(stream.average_rate or 30)
                time_base = float(stream.time_base)  # a Fraction per frame costs more than decoding
                slack = 0.5 / fps  # container timestamps are rounded to the time base
                origin = self.start_s or 0.0
                first_s = origin + start / fps
                if first_s > 1.0:
                    container.seek(int(max(0.0, first_s - 1.0) / stream.time_base), stream=stream,
                                   backward=True, any_frame=False)
                t, last = -np.inf, -1
                for frame in container.decode(stream):
                    t = frame.pts * time_base if frame.pts is not None else t + 1 / fps
                    if self.end_s is not None and t >= self.end_s - slack:
                        break
                    # Indexes come from timestamps, so a seek lands on the same numbering as a
                    # read from the start; strictly increasing even where timestamps round together.
                    index = max(int(round((t - origin) * fps)), last + 1)
                    if t < origin - slack or index < start:
                        continue
                    if frame.width * frame.height > MAX_SOURCE_PIXELS:
                        raise InspectorError(self.path, f"a frame of {frame.width}x{frame.height} exceeds "
                                                        f"the {MAX_SOURCE_PIXELS:,}-pixel limit")
                    last = index
                    yield index, frame
        except InspectorError:
            raise
        except Exception as exc:  # PyAV raises many types for a broken file
            raise InspectorError(self.path, f"cannot decode video ({type(exc).__name__}: {exc})") from None

    def frame(self, index: int, size: Size | None = None) -> npt.NDArray[np.uint8] | None:
        """Frame ``index`` alone (seek + decode from the keyframe before it), or None past the end."""
        for i, rgb in self.iter_frames(size, start=max(0, index)):
            if i >= index:
                return rgb
        return None

    def decode(self, size: Size | None = None, max_bytes: int = DECODE_BUDGET_BYTES
               ) -> npt.NDArray[np.uint8]:
        """Every frame as one (N, H, W, 3) array: for small clips only.

        Raises:
            InspectorError: the clip would take more than ``max_bytes`` (one line naming the
                file, its frame size and the budget), or is unreadable / empty.
        """
        frames: list[npt.NDArray[np.uint8]] = []
        held = 0
        for _, rgb in self.iter_frames(size):
            held += rgb.nbytes
            if held > max_bytes:
                h, w = rgb.shape[:2]
                raise InspectorError(self.path, f"more than {max_bytes / 2**20:.0f} MiB decoded at {w}x{h} "
                                                f"({len(frames)} frames); stream it frame by frame instead")
            frames.append(rgb)
        if not frames:
            window = (f" in [{self.start_s or 0:.3f}, {self.end_s:.3f}) s" if self.end_s is not None else "")
            raise InspectorError(self.path, f"video has no decodable frames{window}")
        return np.stack(frames)

    def __len__(self) -> int:
        """Frames in the clip (counted from the packets, nothing decoded)."""
        return len(self.timestamps())

    def timestamps(self) -> npt.NDArray[np.float64]:
        """(N,) presentation times [s] of the clip's frames from the window's start, read from
        the packets (nothing decoded): ``len(clip.timestamps())`` counts its frames.

        Raises:
            InspectorError: missing or unreadable file.
        """
        import av

        if not self.path.is_file():
            raise InspectorError(self.path, "video file not found")
        try:
            with av.open(str(self.path)) as container:
                stream = container.streams.video[0]
                slack = 0.5 / float(stream.average_rate or 30)
                times = [float(p.pts * stream.time_base) for p in container.demux(stream) if p.pts is not None]
        except Exception as exc:
            raise InspectorError(self.path, f"cannot read video ({type(exc).__name__}: {exc})") from None
        t = np.sort(np.asarray(times, np.float64))
        keep = np.ones(len(t), bool)
        if self.start_s is not None:
            keep &= t >= self.start_s - slack
        if self.end_s is not None:
            keep &= t < self.end_s - slack
        return t[keep] - (self.start_s or 0.0)


class ForwardReader:
    """A clip read forward once, for callers that want frames at non-decreasing indexes: the
    frame shown at an index (the latest one at or before it: a gap in the numbering holds the
    frame before it), at any size.

    Args:
        clip: the clip.
        on_frame: called as ``on_frame(index, rgb)`` for every frame read, wanted or not, at the
            size first asked for (the app encodes them all for display).
    """

    # Frames an encoder may have dropped at a clip's end: the last frame is held over them.
    END_SLACK = 1

    def __init__(self, clip: VideoClip, on_frame: Callable[[int, npt.NDArray[np.uint8]], None] | None = None) -> None:
        self.clip = clip
        self._frames = clip.iter_decoded()
        self._to_rgb = RgbConverter()
        self._on_frame = on_frame
        self._first_size: Size | None = None
        self._current: tuple[int, Any] | None = None  # (index, decoded frame) at or before the target
        self._ahead: tuple[int, Any, npt.NDArray[np.uint8] | None] | None = None
        self._done = False
        self._rgb: dict[Size | None, npt.NDArray[np.uint8]] = {}

    def _pull(self) -> tuple[int, Any, npt.NDArray[np.uint8] | None] | None:
        """The next (index, decoded frame, its RGB at the first size if ``on_frame`` made it)."""
        if self._ahead is not None:
            item, self._ahead = self._ahead, None
            return item
        if self._done:
            return None
        decoded = next(self._frames, None)
        if decoded is None:
            self._done = True
            return None
        rgb = None
        if self._on_frame is not None:
            rgb = self._to_rgb(decoded[1], self._first_size)
            self._on_frame(decoded[0], rgb)
        return (*decoded, rgb)

    def frame_at(self, index: int, size: Size | None = None) -> npt.NDArray[np.uint8] | None:
        """(H, W, 3) frame shown at ``index``, at ``size`` (width, height), or None past the clip."""
        if self._first_size is None:
            self._first_size = size
        while self._current is None or self._current[0] < index:
            item = self._pull()
            if item is None:
                break
            if item[0] > index and self._current is not None:
                self._ahead = item
                break
            # the frame on_frame saw is the one asked for, mostly: scaled once, not twice
            self._current, self._rgb = item[:2], ({self._first_size: item[2]} if item[2] is not None else {})
        if self._current is None or (self._done and index - self._current[0] > self.END_SLACK):
            return None
        if size not in self._rgb:
            self._rgb[size] = self._to_rgb(self._current[1], size)
        return self._rgb[size]

    @property
    def first_size(self) -> Size | None:
        """The size ``on_frame`` sees frames at: the one first asked for (None: the clip's own)."""
        return self._first_size

    def drain(self) -> None:
        """Read the rest of the clip (``on_frame`` sees every frame)."""
        while self._pull() is not None:
            pass


def decode(path: str | Path, start_s: float | None = None, end_s: float | None = None,
           size: Size | None = None, max_bytes: int = DECODE_BUDGET_BYTES
           ) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.float64]]:
    """Every frame of a (small) clip: ((N, H, W, 3) uint8, (N,) times [s] from the window's start).

    See :meth:`VideoClip.decode` (the byte budget) and :meth:`VideoClip.timestamps`.
    """
    clip = VideoClip(Path(path), start_s, end_s)
    frames = clip.decode(size, max_bytes)
    return frames, clip.timestamps()[: len(frames)]


def encode_h264(path: str | Path, frames: Iterable[npt.NDArray[np.uint8]], fps: float, crf: int = 23,
                preset: str = "medium", keyframe_every: int | None = None) -> int:
    """Write RGB frames ((H, W, 3) uint8 each, any iterable) as H.264 (yuv420p) MP4, atomically.

    Frames are encoded as they arrive, so a generator streams a clip of any length through one
    frame of memory. Odd sizes are padded to even (yuv420p needs it). The file appears complete
    or not at all. ``keyframe_every`` frames at most between keyframes (x264's default: 250).

    Returns:
        The number of frames written.

    Raises:
        InspectorError: no frames, or frames that are not (H, W, 3) uint8 of one size.
    """
    import av

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}.mp4")
    try:
        with av.open(str(tmp), mode="w") as container:
            n = _encode_h264_into(container, frames, fps, crf, preset, path, keyframe_every)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return n


def encode_h264_bytes(frames: Iterable[npt.NDArray[np.uint8]], fps: float, crf: int = 23,
                      preset: str = "medium", name: str = "video", keyframe_every: int | None = None) -> bytes:
    """:func:`encode_h264` into memory: the MP4 file's bytes (``name`` labels errors).

    ``keyframe_every`` frames at most between keyframes (x264's default: 250) bounds what a player
    decodes to seek.
    """
    import av

    buffer = io.BytesIO()
    with av.open(buffer, mode="w", format="mp4") as container:
        _encode_h264_into(container, frames, fps, crf, preset, name, keyframe_every)
    return buffer.getvalue()


def _encode_h264_into(container, frames: Iterable[npt.NDArray[np.uint8]], fps: float, crf: int, preset: str,
                      where: str | Path, keyframe_every: int | None = None) -> int:
    import av

    stream = None
    n = 0
    for image in frames:
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[-1] != 3 or image.dtype != np.uint8:
            raise InspectorError(where, f"video frames: expected (H, W, 3) uint8, found "
                                        f"{image.shape} {image.dtype}")
        h, w = image.shape[:2]
        if stream is None:
            stream = container.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
            stream.width, stream.height = w + w % 2, h + h % 2
            stream.pix_fmt = "yuv420p"
            stream.options = {"crf": str(crf), "preset": preset}
            if keyframe_every is not None:
                stream.options = {**stream.options, "g": str(keyframe_every)}
        if (h + h % 2, w + w % 2) != (stream.height, stream.width):
            raise InspectorError(where, f"video frames: frame {n} is {w}x{h}, the first was "
                                        f"{stream.width}x{stream.height}")
        if h % 2 or w % 2:
            image = np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(image), format="rgb24")
        container.mux(stream.encode(frame))
        n += 1
    if stream is None:
        raise InspectorError(where, "video frames: none to write")
    container.mux(stream.encode())
    return n
